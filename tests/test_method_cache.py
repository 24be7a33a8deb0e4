"""Dataclasses' generated methods kept compiled on disk (lumitrace.method_cache): classes
made from kept code behave as compiled ones, nothing untrusted or broken is read, and the
``lumitrace`` command keeps its classes' code once, then compiles none of it again."""
import marshal
import os
import subprocess
import sys
from pathlib import Path

from lumitrace import method_cache

ROOT = Path(__file__).resolve().parents[1]
FILE = f"dataclass-methods-{sys.implementation.cache_tag}.marshal"

#: A script that makes dataclasses (with the cache installed unless told not to) and
#: prints what their generated methods do, then how many texts it compiled itself.
CLASSES = r"""
import dataclasses, sys
sys.path.insert(0, sys.argv[1])
import importlib.util
spec = importlib.util.spec_from_file_location("method_cache", sys.argv[2])
mc = importlib.util.module_from_spec(spec); spec.loader.exec_module(mc)
if sys.argv[3] == "install":
    mc.install()
compiled = []
real = compile
def counting(source, *a, **k):
    compiled.append(source)
    return real(source, *a, **k)
mc.compile = counting  # the module's compile of a text it has not kept

@dataclasses.dataclass(frozen=True)
class Point:
    x: float
    y: float = 2.0
    tags: tuple = dataclasses.field(default_factory=tuple)

@dataclasses.dataclass(order=True)
class Run:
    photons: int
    name: str = "run"

p = Point(1.0)
out = [repr(p), p == Point(1.0, 2.0), p == Point(1.0, 3.0), hash(p) == hash(Point(1.0)),
       repr(Run(5)), Run(5) < Run(6, "a"), Run(5) == Run(5)]
try:
    p.x = 3.0
except dataclasses.FrozenInstanceError as exc:
    out.append("frozen: " + str(exc))
print(out)
print(len(compiled))
"""


def _classes(tmp_path: Path, install: bool = True, cache="cache") -> tuple[str, int]:
    env = dict(os.environ, LUMITRACE_CACHE_DIR="off" if cache == "off" else str(tmp_path / cache))
    p = subprocess.run([sys.executable, "-c", CLASSES, str(ROOT / "service"),
                        method_cache.__file__, "install" if install else "no"],
                       capture_output=True, text=True, env=env, timeout=60, check=True)
    printed, compiled = p.stdout.strip().splitlines()
    return printed, int(compiled)


def test_classes_made_from_kept_code_behave_as_compiled_ones(tmp_path):
    plain, _ = _classes(tmp_path, install=False)
    first, compiled_first = _classes(tmp_path)
    assert (tmp_path / "cache" / FILE).is_file()
    second, compiled_second = _classes(tmp_path)
    assert first == second == plain
    assert "frozen: cannot assign to field 'x'" in plain and "Point(x=1.0, y=2.0" in plain
    # __init__, __repr__, __eq__, __setattr__, __delattr__, __hash__; __init__, __repr__,
    # __eq__ and four comparisons: compiled the first time, all taken from the file after
    assert compiled_first >= 13 and compiled_second == 0


def test_no_cache_folder_compiles_as_python_does(tmp_path):
    printed, compiled = _classes(tmp_path, cache="off")
    assert compiled == 0  # not installed: the interpreter's own exec compiled them
    assert printed == _classes(tmp_path, install=False)[0]
    assert not list(tmp_path.iterdir())


def test_a_broken_file_is_compiled_over_and_written_whole(tmp_path):
    (tmp_path / "cache").mkdir(mode=0o700)
    (tmp_path / "cache" / FILE).write_bytes(b"\xe3not marshal data")
    os.chmod(tmp_path / "cache" / FILE, 0o600)
    printed, compiled = _classes(tmp_path)
    assert compiled >= 13 and printed == _classes(tmp_path, install=False)[0]
    kept = marshal.loads((tmp_path / "cache" / FILE).read_bytes())
    assert len(kept) == compiled and all(isinstance(k, str) for k in kept)


def test_kept_code_is_read_only_from_this_users_unshared_folder(tmp_path):
    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    path = folder / FILE
    path.write_bytes(marshal.dumps({"x = 1": compile("x = 1", "<string>", "exec")}))
    os.chmod(path, 0o600)
    assert list(method_cache._read(path)) == ["x = 1"]
    os.chmod(folder, 0o777)  # others may put code there: nothing is read
    assert method_cache._read(path) == {}
    os.chmod(folder, 0o700)
    os.chmod(path, 0o666)
    assert method_cache._read(path) == {}


def test_the_command_keeps_its_classes_code_once(tmp_path):
    """A first ``lumitrace trace`` writes the code of every dataclass it made; a second
    compiles none anew, so it leaves the file as it was."""
    stage = ROOT / "stages" / "reference" / "isotropic.usda"
    env = dict(os.environ, LUMITRACE_CACHE_DIR=str(tmp_path / "cache"))
    cmd = [sys.executable, "-c", "import sys, lumitrace_launch; sys.exit(lumitrace_launch.main())",
           "trace", str(stage), "--photons", "1000", "--no-pictures", "--quiet",
           "--out", str(tmp_path / "out"), "--no-sublayer"]
    subprocess.run(cmd, env=env, timeout=120, check=True)
    path = tmp_path / "cache" / FILE
    kept = marshal.loads(path.read_bytes())
    assert len(kept) > 150  # the command's 46 classes, several methods each
    assert any("__create_fn__" in text and "photons" in text for text in kept)
    before = path.stat().st_mtime_ns
    subprocess.run(cmd, env=env, timeout=120, check=True)
    assert path.stat().st_mtime_ns == before
