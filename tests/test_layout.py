"""The package's shape: the data flow as folders, imports that only run down the flow,
small modules, an engine that imports without the plotting extra, and maps bit-identical
to the ones the flat layout traced."""
import ast
import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers.paths import ROOT

PACKAGE = ROOT / "service" / "lumitrace"

#: Rank of each part of the package along the data flow. A module may import its own
#: part and parts of lower rank only: the types a stage consumes come from earlier parts
#: (the tracer fills the film's tally; the writers read the film's maps), never back.
RANKS = {
    "errors": 0, "atomic": 0, "filenames": 0,
    "digests": 0,  # a file's SHA-256 and its size-and-time stamp: the standard library only
    # the cache folder and its trusted reads and whole writes: the standard library only
    "cache_files": -0.5,
    "table_cache": 0,  # layout tables kept on disk: numpy and the standard library only
    "pyplot": 0,  # matplotlib's pyplot as every picture loads it: matplotlib only
    "tm25": 0.5,  # the ray-file format: the stage reader reads a light's rays, outputs write them
    "scene": 1, "schema": 1.2,  # the schema names the scene's scattering models as tokens
    "__init__": 1.5,  # registers the schema on import; anything may read __version__
    "stage": 2, "film": 2,
    "delta": 2.5,  # edits the stage, reads it back through the stage reader
    "photometry": 2.8,  # grids and file formats: the tracer reads measured emitter profiles
    "trace": 3,
    "run": 4,
    "publish": 5,
    "report": 6,
    "fit": 6,  # parameters, objectives, the optimiser over traced candidates: above run/
    "serve": 6.5,  # the service: the live view starts fits
    "cli": 7, "api": 7, "__main__": 8,
    "client": 0,  # the standard library only: it runs in a DCC's own Python
    "quick_exit": 0,  # the standard library only: how a command's process ends
}


def _part(module: str) -> str:
    """``lumitrace.trace.tracer`` -> ``trace``; ``lumitrace`` -> ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _imports(path: Path) -> set[str]:
    """Absolute lumitrace modules imported by a source file (any nesting level)."""
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    pkg = list(rel.parts[:-1]) if rel.name != "__init__" else list(rel.parts[:-1])
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg[:len(pkg) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.startswith("lumitrace"):
                names = [f"{mod}.{a.name}" for a in node.names]
                out.add(mod)
                out.update(n for n in names if (PACKAGE.parent / n.replace(".", "/")).is_dir()
                           or (PACKAGE.parent / (n.replace(".", "/") + ".py")).exists())
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.startswith("lumitrace"))
    return out


MODULES = sorted(PACKAGE.rglob("*.py"))


def test_every_part_has_a_rank():
    parts = {p.relative_to(PACKAGE).parts[0].removesuffix(".py") for p in MODULES}
    assert parts <= set(RANKS), parts - set(RANKS)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_only_run_down_the_flow(path):
    own = path.relative_to(PACKAGE).parts[0].removesuffix(".py")
    bad = [m for m in _imports(path)
           if _part(m) != own and RANKS[_part(m)] >= RANKS[own] and _part(m) != "__init__"]
    assert not bad, f"{path.relative_to(PACKAGE)} imports {bad} (rank {RANKS[own]})"


@pytest.mark.parametrize("path", sorted((PACKAGE / "publish").glob("*.py")),
                         ids=lambda p: p.name)
def test_writing_knows_no_session_and_traces_nothing(path):
    """publish/ writes the result it is handed: it imports neither the sessions of run/
    nor the tracer (exit rays come out of trace/, the result record from film/)."""
    bad = [m for m in _imports(path) if m.startswith(("lumitrace.run", "lumitrace.trace"))]
    assert not bad, f"publish/{path.name} imports {bad}"


def test_import_graph_has_no_cycle():
    graph = {}
    for path in MODULES:
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        # "from . import x" names the package only to reach its module x: no edge to it
        graph[name] = {m for m in _imports(path) if m != name and not name.startswith(m + ".")}
    state = {}

    def visit(node, stack):
        state[node] = 1
        for nxt in graph.get(node, ()):
            if nxt not in graph:
                continue
            if state.get(nxt) == 1:
                raise AssertionError(" -> ".join(stack + [nxt]))
            if nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for n in graph:
        if n not in state:
            visit(n, [n])


#: Modules allowed to be longer, and why.
LONG_MODULES: dict[str, int] = {}


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_over_700_lines(path):
    limit = LONG_MODULES.get(str(path.relative_to(PACKAGE)), 700)
    assert len(path.read_text().splitlines()) <= limit


def test_engine_imports_without_the_plotting_extra():
    code = ("import sys\n"
            "class Block:\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            "        if name.split('.')[0] in ('matplotlib', 'pyvista', 'vtk'):\n"
            "            raise ImportError('blocked: ' + name)\n"
            "sys.meta_path.insert(0, Block())\n"
            "import lumitrace.trace.tracer, lumitrace.film.convergence, lumitrace.run.session\n"
            "import lumitrace.publish.outputs, lumitrace.stage.reader\n"
            "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


#: sha256 of the int64 counts, photons, absorbed and cut of every emitter, traced with
#: 200,000 photons, 16 texels per face, seed 7 by the layout before the data-flow folders.
#: The compiled photon kernels draw directions with float64 trigonometry where numpy drew
#: them in float32: in the integrating sphere's long diffuse paths that changed some
#: photons' paths once (new hash); the other stages' counts came out identical. Embree then
#: took each part's triangles as quads, whose float32 distances differ from a triangle
#: mesh's in the last bits: the integrating sphere's and the paraboloid's counts changed
#: (new hashes), the others' are the same.
FLAT_LAYOUT_HASHES = {
    "reference/isotropic": "74885995c26e1e6419f1f59f4a44c41858dd613b19419eb87f37d1defaa5c37f",
    "reference/lambertian_disc": "a818f3a50a5ffb320f3d08cbaab0612a293b7661485ddda25e3e44ea2f9d12c4",
    # (the sphere's long diffuse paths meet its 32,064 triangles at their shared edges:
    # the hits' last bits, hence a few paths, follow the CPU's vector unit Embree picks;
    # each hash was seen on one kind of CPU, the second on an AMD EPYC without AVX-512)
    "reference/integrating_sphere": (
        "2ef6c95572fce44173d768bf8d99758b17a54b885d029d6d7f5e20a2016cb42a",
        "b6fd93a5241f194af33070665172a3a17ef120eadea3dd9fc7e0d313e21f826c"),
    "reference/fresnel_slab": "854719614bc656974fbcb22e90c35e5c6ad5f9965e4c4d17dba4ec2a9b39b877",
    "reference/paraboloid":
        "a8bb1c7b9efb5dc4242680d71a351f829e4b3a7de0b64b677f7673e69685d6ae",
    "downlight": "a95271697236614215f3f8482d2210f9dafaa6983c3423f223144dcafdce2449",
}


@pytest.mark.parametrize("name", sorted(FLAT_LAYOUT_HASHES))
def test_maps_are_bit_identical_to_the_flat_layout(name):
    from lumitrace.run.session import TraceSettings, run
    from lumitrace.stage.reader import read_stage

    scene = read_stage(ROOT / "stages" / f"{name}.usda")
    r = run(scene, TraceSettings(photons=200_000, resolution=16, seed=7, threads=2,
                                 workers="threads"))
    h = hashlib.sha256()
    for t in r.accumulator.emitters:
        h.update(np.ascontiguousarray(t.counts, dtype="<i8").tobytes())
        h.update(np.array([t.photons, t.absorbed, t.cut], dtype="<i8").tobytes())
    want = FLAT_LAYOUT_HASHES[name]
    assert h.hexdigest() in (want if isinstance(want, tuple) else (want,))


def test_tests_mirror_the_package():
    """Test folders are named for the package's parts; test modules import shared code from
    ``tests/helpers`` (or the stress library in ``tools/``), never from each other, and
    ``tools/`` imports nothing from ``tests/``."""
    tests = ROOT / "tests"
    parts = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    # the packages beside lumitrace in service/ (the Blender add-on) have a folder each
    parts |= {p.name for p in PACKAGE.parent.iterdir() if (p / "__init__.py").exists()}
    folders = {p.name for p in tests.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))}
    assert folders - {"helpers", "data"} <= parts, folders - parts
    test_modules = {p.stem for p in tests.rglob("test_*.py")}
    for path in list(tests.rglob("*.py")) + list((ROOT / "tools").glob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                top = name.split(".")[0]
                assert top not in test_modules, f"{path.relative_to(ROOT)} imports {name}"
                if path.parent.name == "tools":
                    assert top not in ("tests", "helpers", "conftest"), \
                        f"{path.relative_to(ROOT)} imports {name}"
