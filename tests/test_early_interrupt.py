"""A SIGINT that arrives once lumitrace's first statement has run stops the run (exit 130,
nothing written), even in a process started with SIGINT ignored, as a shell script's
background job is: the entry point and the package set their recorders before anything
else. (Before that first statement the interpreter is starting, and an ignored signal is
gone: ``tools/early_interrupt.py`` measures that window.)"""
from __future__ import annotations

import hashlib
import os
import shutil
import signal
import subprocess
import sys

import pytest
from helpers.paths import REFERENCE, ROOT

#: The process signals itself right after importing lumitrace's first module: an event,
#: not a delay. The package's own ``__main__`` runs as ``python -m lumitrace`` runs it.
STARTS = {
    "lumitrace": "import lumitrace_launch; os.kill(os.getpid(), signal.SIGINT); "
                 "sys.exit(lumitrace_launch.main())",
    "python -m lumitrace": "sys.argv[0] = '-m'; import lumitrace; "
                           "os.kill(os.getpid(), signal.SIGINT); import runpy; "
                           "runpy.run_module('lumitrace', run_name='__main__', "
                           "alter_sys=True)",
}


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _digest(folder) -> str:
    return hashlib.sha256(b"".join((folder / n).read_bytes() for n in (
        "iso.ies", "iso.ldt", "iso.lumitrace.usda"))).hexdigest()


@pytest.mark.parametrize("launcher", sorted(STARTS))
def test_sigint_after_the_first_statement_stops_a_run_started_ignoring_it(tmp_path,
                                                                          launcher):
    stage = tmp_path / "iso.usda"
    shutil.copy(REFERENCE / "isotropic.usda", stage)
    args = ["trace", str(stage), "--photons", "20000", "--resolution", "8", "--no-pictures",
            "--no-progress", "--quiet"]
    env = {**os.environ, "PYTHONPATH": str(ROOT / "service")}
    assert subprocess.run([sys.executable, "-m", "lumitrace", *args], env=env).returncode == 0
    before = _digest(tmp_path)
    p = subprocess.run([sys.executable, "-c", f"import os, signal, sys; {STARTS[launcher]}",
                        *args], capture_output=True, text=True, env=env, timeout=300,
                       preexec_fn=_ignore_sigint)
    assert p.returncode == 130, (p.returncode, p.stderr[-2000:])
    assert p.stderr.strip().splitlines() == [
        "lumitrace: SIGINT: interrupted; nothing was written, earlier outputs are unchanged"]
    assert _digest(tmp_path) == before
