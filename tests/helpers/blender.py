"""The bpy environment the Blender tests run their scripts in (``sh tools/setup.sh
--blender`` makes it): Blender 4.5 as a Python module, in a virtual environment of its own
since it pins numpy below 2."""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from helpers.paths import ROOT

SCRIPTS = ROOT / "tests" / "lumitrace_blender" / "scripts"
TOOLS = ROOT / "tools"


def blender_python() -> Path:
    """The bpy environment's interpreter (``LUMITRACE_BLENDER_PYTHON``, else
    ``.venv-blender`` of the checkout); skips the test, saying why, where there is none."""
    given = os.environ.get("LUMITRACE_BLENDER_PYTHON")
    python = Path(given) if given else ROOT / ".venv-blender" / "bin" / "python"
    if not python.exists():
        pytest.skip(f"no bpy environment at {python}: `sh tools/setup.sh --blender` makes "
                    "it (Blender 4.5 as a Python module, Python 3.11)")
    return python


def run_bpy(script: str, *args, timeout: float = 300.0) -> dict:
    """Run ``tests/lumitrace_blender/scripts/SCRIPT`` (or ``tools/SCRIPT``) in the bpy
    environment with the add-on on its path; returns the JSON object its last line prints.
    A script still running 10 s before ``timeout`` prints every thread's stack and exits,
    so a stall says where it is."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "service")}
    path = SCRIPTS / script if (SCRIPTS / script).exists() else TOOLS / script
    runner = ("import faulthandler, os, runpy, sys; "
              f"faulthandler.dump_traceback_later({max(1.0, timeout - 10.0)}, exit=True); "
              "sys.argv = sys.argv[1:]; sys.path.insert(0, os.path.dirname(sys.argv[0])); "
              "runpy.run_path(sys.argv[0], run_name='__main__')")
    p = subprocess.run([str(blender_python()), "-c", runner, str(path), "--",
                        *map(str, args)],
                       capture_output=True, text=True, timeout=timeout, env=env)
    lines = [line for line in p.stdout.splitlines() if line.startswith("{")]
    assert p.returncode == 0 and lines, f"{script} failed ({p.returncode}):\n" \
        f"{p.stdout[-3000:]}\n{p.stderr[-5000:]}"
    return json.loads(lines[-1])
