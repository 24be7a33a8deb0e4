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
                       capture_output=True, text=True, timeout=120, check=True,
                       # a first run: USD reads the stage (no kept scene of another test's)
                       env={**os.environ, "LUMITRACE_CACHE_DIR": str(tmp_path / "cache")})
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
