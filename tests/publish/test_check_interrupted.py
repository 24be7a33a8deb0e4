"""``lumitrace check`` after a run killed (SIGKILL) in the middle of its commit, its journal
pending and the files of two runs side by side: the check finishes the publishing as the
next trace would and judges the complete set, never the half-published one; a journal it
may not finish (not this user's lumitrace's) is the distinct verdict ``interrupted``."""
from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.paths import REFERENCE

#: A trace killed (SIGKILL: no handler runs) as its commit renames the staged LDT onto
#: its target: the IES and EXRs are already the new run's, the LDT, the JSON and the
#: result layer still the last run's.
_KILLED_MID_COMMIT = """
import os, signal, sys
real = os.replace

def replace(src, dst, *args, **kwargs):
    if "-staging-" in str(src) and "-staging-" not in str(dst) and str(dst).endswith(".ldt"):
        os.kill(os.getpid(), signal.SIGKILL)
    return real(src, dst, *args, **kwargs)

os.replace = replace
from lumitrace.cli import main
sys.exit(main(sys.argv[1:]))
"""
ARGS = ("--photons", "60000", "--resolution", "16", "--threads", "1", "--no-progress",
        "--no-pictures")


def _run(*args, script: str | None = None) -> subprocess.CompletedProcess:
    start = ["-c", script] if script else ["-m", "lumitrace"]
    return subprocess.run([sys.executable, *start, *map(str, args)], capture_output=True,
                          text=True, timeout=300)


def _ids(folder: Path) -> dict:
    from lumitrace.publish.runs import published_run_ids

    return published_run_ids(folder, "disc")


def _check(stage: Path) -> tuple[int, dict]:
    p = _run("check", stage, "--json")
    return p.returncode, json.loads(p.stdout.strip().splitlines()[-1])


@pytest.fixture
def half_published(tmp_path):
    """The disc traced, then traced again and killed mid-commit: (stage, the first run's
    id, the killed run's id)."""
    stage = tmp_path / "disc.usda"
    shutil.copy(REFERENCE / "lambertian_disc.usda", stage)
    assert _run("trace", stage, *ARGS, "--seed", "1").returncode == 0
    (first,) = set(_ids(tmp_path).values())
    killed = _run("trace", stage, *ARGS, "--seed", "2", script=_KILLED_MID_COMMIT)
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    ids = _ids(tmp_path)
    assert (tmp_path / ".disc.lumitrace-journal").exists()
    assert ids["ies"] == ids["exr"] != first and ids["ldt"] == first  # two runs' files
    return stage, first, ids["exr"]


def test_check_finishes_a_half_published_set_and_judges_the_whole(half_published):
    stage, first, killed = half_published
    code, said = _check(stage)
    assert said["status"] in ("current", "not converged") and code in (0, 3), said
    assert any("completed the interrupted publishing" in d for d in said["recovered"])
    ids = _ids(stage.parent)
    assert set(ids.values()) == {killed}, ids  # one set: the run that committed
    assert not list(stage.parent.glob(".disc.lumitrace-*"))
    from pxr import Sdf

    layer = Sdf.Layer.OpenAsAnonymous(str(stage.with_name("disc.lumitrace.usda")))
    seed = layer.GetAttributeAtPath("/Luminaire.lumitrace:result:seed").default
    assert seed == 2 and said["photons"] == 60000  # judged on the run that committed
    assert _check(stage) == (code, {**said, "recovered": []})


def test_a_journal_it_may_not_finish_is_the_verdict_interrupted(half_published):
    stage, first, killed = half_published
    journal = stage.parent / ".disc.lumitrace-journal"
    record = json.loads(journal.read_text())
    journal.write_text(json.dumps({**record, "mac": "0" * 64}))  # not this user's key's

    def files():
        return {str(p.relative_to(stage.parent)): p.read_bytes()
                for p in stage.parent.rglob("*") if p.is_file() and p.suffix != ".lock"}

    before = files()
    assert any("-staging-" in name for name in before)  # the staged files it names
    code, said = _check(stage)
    assert code == 4 and said["status"] == "interrupted", said
    assert "interrupted" in said["message"] and journal.name in said["message"]
    assert files() == before  # nothing it names was touched
