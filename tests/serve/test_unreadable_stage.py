"""A stage made unreadable while a delta arrives (a colleague's `chmod`, a DCC saving it
under another user's rules) locks nobody out: the result layer the service writes then
keeps a mode its owner can read and write (it used to take the stage's mode, 000, and
every later run, the service's and `lumitrace trace`'s, refused it), later revisions and
runs write as before, and a layer that cannot be read is said to be unreadable, never
"not a result layer lumitrace wrote"."""
from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from service_process import Service

from helpers.paths import REFERENCE

FAST = ("--photons", 20_000, "--resolution", 8, "--threads", 1, "--seed", 3)
SOURCE = "/Luminaire/Source"
FLUX = "lumitrace:luminousFlux"
NOBODY = 65534


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def _written_or_failed(service, revision: int):
    """The first ``written`` or ``error`` event of ``revision``."""
    return service.wait_event(lambda e: e.kind in ("written", "error")
                              and e.data.get("revision") == revision, timeout=120)


def test_a_stage_unreadable_while_a_delta_arrives_leaves_a_layer_the_next_run_takes(
        tmp_path):
    stage = tmp_path / "isotropic.usda"
    shutil.copy(REFERENCE / "isotropic.usda", stage)
    layer = tmp_path / "isotropic.lumitrace.usda"
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        before = _mode(layer)
        assert before & 0o600 == 0o600
        stage.chmod(0)
        try:
            assert s.client.set(SOURCE, FLUX, 500.0)["revision"] == 1
            _written_or_failed(s, 1)
            assert _mode(layer) == before, oct(_mode(layer))  # not the stage's 000
        finally:
            stage.chmod(0o644)
        assert s.client.set(SOURCE, FLUX, 700.0)["revision"] == 2
        s.wait_done(2, pictures=False)
        said = [e.data.get("message", "") for e in s.client.history(0) if e.kind == "error"]
        assert not any("is not a result layer" in m for m in said), said
        assert _mode(layer) == before
        assert s.stop()[0] == 0
    run = subprocess.run([sys.executable, "-m", "lumitrace.cli", "trace", str(stage),
                          "--photons", "5000", "--resolution", "8", "--threads", "1",
                          "--json"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout.strip().splitlines()[-1])["photons"] == 5000
    assert _mode(layer) == before


def _claim_as(uid: int | None, stage: Path) -> str:
    """The message of claiming the stage's outputs (as the user ``uid`` in a child
    process where given: root reads any file)."""
    from lumitrace.errors import OutputError
    from lumitrace.filenames import output_names, stage_name
    from lumitrace.publish.ownership import claim_outputs

    names = {n.split(stage_name(stage), 1)[1]: stage.parent / n
             for n in output_names(stage_name(stage))}
    paths = {"result_layer": names.pop(".lumitrace.usda"), **{k: v for k, v in
                                                                names.items()}}

    def claim() -> str:
        try:
            claim_outputs(stage, paths)
        except OutputError as exc:
            return str(exc)
        return "claimed"

    if uid is None:
        return claim()
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: drop to ``uid``, claim, say what it said
        try:
            os.close(read)
            os.setgroups([])
            os.setgid(uid)
            os.setuid(uid)
            os.write(write, claim().encode())
        finally:
            os._exit(0)
    os.close(write)
    with os.fdopen(read, "rb") as fh:
        said = fh.read().decode()
    os.waitpid(pid, 0)
    return said


@pytest.fixture
def folder():
    """A folder another user can reach (pytest's own are private to their user)."""
    path = Path(tempfile.mkdtemp(prefix="lumitrace-unreadable-"))
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


def test_a_result_layer_that_cannot_be_read_is_said_to_be_unreadable(folder):
    """A result layer lumitrace wrote, left mode 000 (as an earlier version left it): the
    refusal names the file and says it cannot be read, never that lumitrace did not
    write it."""
    tmp_path = folder
    stage = tmp_path / "isotropic.usda"
    shutil.copy(REFERENCE / "isotropic.usda", stage)
    run = subprocess.run([sys.executable, "-m", "lumitrace.cli", "trace", str(stage),
                          "--photons", "2000", "--resolution", "8", "--threads", "1"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    layer = tmp_path / "isotropic.lumitrace.usda"
    uid = None
    if os.geteuid() == 0:  # root reads a mode-000 file: claim as another user
        uid = NOBODY
        for path in (tmp_path, *tmp_path.iterdir()):
            os.chown(path, NOBODY, NOBODY)
    assert _claim_as(uid, stage) == "claimed"
    layer.chmod(0)
    said = _claim_as(uid, stage)
    assert str(layer) in said and "cannot be read" in said, said
    assert "not a result layer lumitrace wrote" not in said, said
    layer.chmod(0o644)
    assert _claim_as(uid, stage) == "claimed"
