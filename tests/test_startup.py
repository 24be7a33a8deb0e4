"""What a small ``lumitrace trace`` loads: only what it uses (each module a command loads
costs every command its start; the run's own cost is measured by tools/startup.py)."""
import os
import re
import subprocess
import sys
from pathlib import Path

from lumitrace import cli

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = "import sys, lumitrace_launch; sys.exit(lumitrace_launch.main())"


def test_a_small_trace_loads_no_module_it_does_not_use(tmp_path):
    stage = ROOT / "stages" / "reference" / "isotropic.usda"
    p = subprocess.run([sys.executable, "-X", "importtime", "-c", LAUNCH, "trace", str(stage),
                        "--photons", "1000", "--no-pictures", "--quiet", "--no-sublayer",
                        "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=120, check=True)
    loaded = set(re.findall(r"^import time:.*\|\s*([\w.]+)$", p.stderr, re.M))
    assert {"lumitrace.cli", "lumitrace.trace.compiled", "pxr.UsdLux"} <= loaded
    unused = {"concurrent.futures",  # a round of one batch is traced in the calling thread
              "pxr.UsdUtils", "zipfile",  # the reader needs UsdUtils' delegate alone
              "uuid", "lumitrace.run.cluster", "numba", "multiprocessing", "vtk", "pyvista"}
    assert not loaded & unused


def test_each_commands_parser_alone_parses_as_the_whole_one():
    for argv in (["trace", "a.usda", "--photons", "2e6", "--target-error", "0.02", "--json"],
                 ["serve", "a.usda", "--port", "0", "--target-error", "0.01"],
                 ["check", "a.usda", "--json"], ["edits", "merge", "a.usda"],
                 ["report", "a.usda", "--time", "3"], ["bench", "--seconds", "2"],
                 ["rays", "a.usda", "--photons", "1000"],
                 ["fit", "a.usda", "--target", "t.ldt", "--vary", "/L/M.lumitrace:reflectance",
                  "/L/P.xformOp:translate[2]=-1:1", "--evaluations", "40"]):
        assert cli.build_parser(argv[0]).parse_args(argv) == cli.build_parser().parse_args(argv)


def test_the_command_loads_lumitrace_without_collections_and_resumes_them():
    code = ("import gc, lumitrace_launch; main, _ = lumitrace_launch._load_cli(); "
            "import lumitrace.cli; "
            "print(gc.isenabled(), gc.get_freeze_count(), main is lumitrace.cli.main)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True).stdout.split()
    assert out[0] == "True" and int(out[1]) > 10_000  # what loading made: frozen
    assert out[2] == "True"


def test_a_trace_reading_usd_loads_its_modules_without_collections_and_ends_collecting(
        tmp_path):
    """USD's modules and the trace command's load with the collector paused (they set off
    some 40 collections, about 7 ms, that found nothing); it runs again for the trace."""
    stage = tmp_path / "isotropic.usda"
    stage.write_text((ROOT / "stages" / "reference" / "isotropic.usda").read_text())
    code = ("import atexit, gc, sys; n = [0]; gc.callbacks.append("
            "lambda phase, info: n.__setitem__(0, n[0] + (phase == 'start'))); "
            "atexit.register(lambda: print('collections', n[0], gc.isenabled(), "
            "file=sys.stderr)); " + LAUNCH)
    p = subprocess.run([sys.executable, "-c", code, "trace", str(stage), "--photons", "1000",
                        "--no-pictures", "--quiet", "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=120, check=True,
                       env={**os.environ, "LUMITRACE_CACHE_DIR": "off"})
    count, running = re.search(r"collections (\d+) (\w+)", p.stderr).groups()
    assert int(count) < 10 and running == "True", p.stderr


def test_a_paused_collector_freezes_what_loaded_and_resumes_as_it_was():
    import gc

    from lumitrace.loading import collector_paused

    assert gc.isenabled()
    frozen = gc.get_freeze_count()
    try:
        with collector_paused():
            kept = [[i] for i in range(1000)]  # what a module would make
            assert not gc.isenabled()
            with collector_paused():  # inside another: still paused after it
                pass
            assert not gc.isenabled()
        assert gc.isenabled() and gc.get_freeze_count() >= frozen + len(kept)
        gc.disable()
        with collector_paused():
            pass
        assert not gc.isenabled()  # it was paused before: left so
    finally:
        gc.enable()
        gc.unfreeze()
