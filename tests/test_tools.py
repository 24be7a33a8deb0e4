"""Every script in ``tools/`` runs (with a quick argument set, or ``--help`` where a full
run is long or needs a browser), and every example delta of the service guide
(docs/guide/service.md) is accepted by a real ``lumitrace serve`` of the demo stage: none of
them can rot unseen."""
from __future__ import annotations

import ast
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from service_process import Service

from helpers.paths import ROOT
from lumitrace.client import ServiceError

TOOLS = ROOT / "tools"
DEMO = ROOT / "stages" / "downlight.usda"
REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
#: Quick settings that converge fast on the demo.
QUICK = ("--target-error", 0.3, "--resolution", 8, "--threads", 1, "--quiet")

#: Each script's quick run ({out}: a fresh folder). A full run of those given "--help" is
#: minutes long or needs a browser; they are exercised by their own tests where there are.
RUNS: dict[str, tuple[str, ...]] = {
    "accuracy_page.py": ("--photons", "20000", "--seeds", "1", "--target-error", "0.3",
                         "--dry-run", "--images", "{out}"),
    "application_cost.py": ("--photons", "20000", "--repeats", "1"),
    "beam_angle_seeds.py": ("--seeds", "2", "--photons", "20000", "--only", "disc"),
    "bench.py": ("--seconds", "0.5", "--threads", "1"),
    "colour_cost.py": ("--photons", "20000", "--repeats", "1"),
    "early_interrupt.py": ("--delays", "0", "--repeats", "1", "--dispositions", "default"),
    "dask_bench.py": ("--photons", "100000", "--resolution", "8", "--small-batches", "10"),
    "deliverables_cost.py": ("--photons", "20000", "--repeats", "1", "--no-pictures"),
    "convergence_report.py": ("--seconds", "0.3", "--resolution", "8", "--out", "{out}",
                              "--reference-photons", "20000", "--thresholds", "1"),
    "files_error_seeds.py": ("--seeds", "2", "--photons", "20000", "--scenes", "lambertian"),
    "fit_design.py": ("--evaluations", "6", "--photons", "4096"),
    "fit_speed.py": ("--evaluations", "6", "--photons", "4096", "--max-photons", "8192",
                     "--naive", "schedule", "--target-photons", "100000",
                     "--confirm-photons", "16384"),
    "generate_schema.py": ("--check",),
    "many_emitters.py": ("--side", "3", "--photons", "20000", "--repeats", "1",
                         "--resolution", "8", "--threads", "1"),
    "live_loop_bench.py": ("--edits", "1", "--client", "page"),
    "live_fit_bench.py": ("--repeats", "1", "--evaluations", "4", "--photons", "4096",
                          "--target-photons", "100000"),
    "live_view_screenshot.py": ("--help",),  # drives headless Chromium for a minute
    "part_edit_bench.py": ("--triangles", "20000", "--repeats", "1"),
    "performance_page.py": ("--quick",),
    "make_stages.py": ("--check",),
    "opening_seeds.py": ("--seeds", "2", "--photons", "8192", "--reference-photons", "16384",
                         "--stages", "disc"),
    "photometry_accuracy.py": ("--photons", "20000", "--stages", "isotropic"),
    "profile_run.py": ("--photons", "20000"),
    "publish_stress.py": ("--runs", "1", "--bursts", "1", "--seconds", "1"),
    "retrace_bench.py": ("--photons", "20000", "--stages", "downlight", "--threads", "1"),
    "seed_study.py": ("--seeds", "2", "--photons", "20000", "--stages", "lambertian_disc"),
    "service_pictures.py": ("--edits", "1"),
    "side_by_side.py": ("--photons", "20000", "--repeats", "1", "--max-photons", "20000",
                        "--resolution", "8", "--scenes", "isotropic", "--peer", "none"),
    "solid_bench.py": ("--solids", "1"),
    "startup.py": ("--photons", "10000", "--repeats", "1"),
    "stress.py": ("--photons", "20000", "--fuzz-seconds", "0.5", "--only", "furnace"),
    "symmetry_seeds.py": ("stages/reference/lambertian_disc.usda", "--seeds", "1",
                          "--target", "0.2", "--reference-photons", "20000"),
    "viewer_bench.py": ("--help",),  # drives headless Chromium for minutes
}
#: Checks that say nothing when all is well (their exit status says it).
SILENT = ("generate_schema.py", "make_stages.py")
#: Modules other scripts and the tests import: importing them is their run.
MODULES = ("headless_browser.py", "service_process.py", "stress_cases.py")
#: Run against a live service below (it needs one), or with its output checked below.
SERVED = ("edit_reflector.py", "service_load.py")
#: Not run here, with the reason.
SKIPPED = {
    "peer": "a C++/Rust peer tracer built with an external toolchain (side_by_side.py "
            "runs it where built; --peer none here)",
    "setup.sh": "installs packages into the environment; only its syntax is checked",
    **{name: "runs in Blender's own Python (.venv-blender): tests/lumitrace_blender runs "
             "it, and skips saying why where that environment is missing"
       for name in ("blender_install.py", "blender_live_session.py", "blender_roundtrip.py")},
}


def _script_names() -> list[str]:
    return sorted(p.name for p in TOOLS.iterdir()
                  if not p.name.startswith((".", "__")) and p.name != "__pycache__")


def test_every_tool_is_covered():
    """A script added to tools/ must be given a quick run here (or a reason not to)."""
    covered = set(RUNS) | set(MODULES) | set(SERVED) | set(SKIPPED)
    assert set(_script_names()) == covered, set(_script_names()) ^ covered


def _run(args: list[str], cwd: Path, timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.parametrize("name", sorted(RUNS))
def test_tool_runs(name, tmp_path):
    args = [a.replace("{out}", str(tmp_path / "out")) for a in RUNS[name]]
    run = _run([str(TOOLS / name), *args], tmp_path)
    assert run.returncode == 0, f"{name}: {run.stdout[-2000:]}\n{run.stderr[-3000:]}"
    assert run.stdout.strip() or name in SILENT, f"{name} printed nothing"


@pytest.mark.parametrize("name", MODULES)
def test_tool_module_imports(name, tmp_path):
    code = f"import sys; sys.path.insert(0, {str(TOOLS)!r}); import {name[:-3]}"
    run = _run(["-c", code], tmp_path)
    assert run.returncode == 0, run.stderr[-3000:]


def test_setup_script_parses():
    """setup.sh installs packages (not run here); a shell parses it."""
    run = subprocess.run(["sh", "-n", str(TOOLS / "setup.sh")], capture_output=True,
                         text=True, timeout=30)
    assert run.returncode == 0, run.stderr


@pytest.mark.skip(reason=SKIPPED["peer"])
def test_peer_tracer():
    """tools/peer: built and run by side_by_side.py where its toolchain is installed."""


def test_service_load_loses_no_delta_beside_hostile_clients(tmp_path):
    """tools/service_load.py's load run, alone and beside its hostile clients (200 event
    streams, slow readers, bodies at and over the size limit): every delta answered 200
    is kept, bodies at the limit are accepted and those over it refused with 413."""
    run = _run([str(TOOLS / "service_load.py"), "--only", "load", "--clients", "2",
                "--deltas", "3"], tmp_path, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-3000:]
    report = json.loads(run.stdout)
    for name in ("load", "load_hostile"):
        load = report[name]
        assert load["accepted"] == 6 and load["failures"] == 0, load
        assert load["accepted_deltas_lost"] == 0 and load["revisions_unique_and_contiguous"]
    hostile = report["load_hostile"]["hostile"]
    assert hostile["streams_open"] == 200 and hostile["stream_bytes"] > 0, hostile
    assert hostile["big_accepted"] >= 1 and hostile["big_413"] >= 1, hostile
    assert not hostile["big_other"], hostile


# ------------------------------------------------------------------------------------------
# Against a live service of the demo
# ------------------------------------------------------------------------------------------

@pytest.fixture
def demo(tmp_path) -> Path:
    path = tmp_path / "downlight.usda"
    shutil.copy(DEMO, path)
    return path


def _service_section() -> str:
    return (ROOT / "docs" / "guide" / "service.md").read_text()


def readme_batches() -> list[list[dict]]:
    """Every JSON block of the service guide that is a batch of deltas."""
    blocks = re.findall(r"```json\n(.*?)```", _service_section(), re.S)
    return [json.loads(b)["deltas"] for b in blocks if '"deltas"' in b]


def readme_client_calls() -> list[tuple[str, list]]:
    """The ``c.set(...)`` style calls of the service guide's client example: (method,
    args)."""
    calls = []
    for line in re.findall(r"^(?:\w+ = )?c\.(\w+\(.*\))", _service_section(), re.M):
        call = ast.parse(line.split("  #")[0].strip()).body[0].value
        calls.append((call.func.id, [ast.literal_eval(a) for a in call.args]))
    return calls


def test_readme_batches_are_found():
    batches = readme_batches()
    assert batches and sum(map(len, batches)) >= 9
    assert {d["op"] for b in batches for d in b} == {
        "set", "transform", "bind", "add", "remove", "active", "variant", "layer"}
    assert readme_client_calls()


def test_every_readme_example_delta_is_accepted_by_the_demo(demo, tmp_path):
    """Each example batch is accepted as a whole (200) on the demo; then, on a fresh copy,
    each of its deltas alone, in order, is accepted and changes what is traced (effect not
    ``none``; the ``layer`` delta only adds a variant set the next delta selects), and so
    is the client example's call; a ``lumitrace:`` name no schema defines is refused,
    naming the nearest."""
    with Service(demo, *QUICK) as s:
        for batch in readme_batches():
            answer = s.client.send(batch)
            assert answer["effect"]["kind"] != "none", answer
        s.wait_done(s.client.status()["revision"], pictures=False)
    single = tmp_path / "single"
    single.mkdir()
    shutil.copy(DEMO, single / "downlight.usda")
    with Service(single / "downlight.usda", *QUICK) as s:
        for delta in [d for b in readme_batches() for d in b]:
            answer = s.client.send([delta])
            if delta["op"] != "layer":
                assert answer["effect"]["kind"] != "none", (delta, answer)
        for method, args in readme_client_calls():
            answer = getattr(s.client, method)(*args)
            assert answer["revision"] > 0
        for typed in ({}, {"type": "float"}):  # a misspelt name of ours, with or without
            with pytest.raises(ServiceError) as refused:  # a type, would trace as nothing
                s.client.send([{"op": "set", "path": REFLECTOR, "value": 0.5,
                                "property": "lumitrace:diffuseReflectance", **typed}])
            assert refused.value.status == 422
            assert "did you mean lumitrace:reflectance" in refused.value.problems[0]["why"]
        status = s.wait_done(s.client.status()["revision"], pictures=False)
        assert status["last_error"] is None


def test_edit_reflector_prints_the_beam_angle_as_the_result_refines(demo):
    """tools/edit_reflector.py against a real service: each written result is a line with
    photons, error, beam angle and peak, ending with the one with pictures."""
    with Service(demo, *QUICK) as s:
        s.wait_done(0)
        run = _run([str(TOOLS / "edit_reflector.py"), "--url", s.url, "--reflectance",
                    "0.6"], demo.parent)
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.strip().splitlines()
    assert lines[0].startswith("revision 1: material edit")
    assert all("beam angle" in line and " cd" in line for line in lines[1:])
    assert lines[-1].endswith("(with pictures)")
