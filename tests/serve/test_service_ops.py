"""``lumitrace serve`` as an operator meets it, each case on a real server process on a free
loopback port: saves that land while the service writes its result, a stage that vanishes
and comes back, restarts (revisions and event ids), what it says on stderr, the edits
commands while it serves, heavy deltas, and the scripts in ``tools/``."""
from __future__ import annotations

import difflib
import html
import json
import os
import random
import shutil
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from pxr import Usd
from service_process import Service

from lumitrace.delta.protocol import MAX_ARRAY_VALUES

from helpers.paths import ROOT

DEMO = ROOT / "stages" / "downlight.usda"
REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
SPEC = "lumitrace:specularReflectance"
#: Quick settings that converge: ``lumitrace check`` can say "current" (exit 0).
QUICK = ("--target-error", 0.3, "--resolution", 8, "--threads", 1, "--seed", 5)
FLUX = "lumitrace:luminousFlux = 1200"
#: How long after a result layer is replaced a save lands (s): inside the stage step.
DELAYS = (0.0005, 0.001, 0.0015)


@pytest.fixture
def stage(tmp_path) -> Path:
    path = tmp_path / "downlight.usda"
    shutil.copy(DEMO, path)
    return path


def _save(path: Path, text: str) -> None:
    """Save a file as a DCC does: a temporary file renamed over it."""
    tmp = path.with_name(f".{path.name}.saving")
    tmp.write_text(text)
    os.replace(tmp, path)


def _signature(path: Path):
    """What changes when a file is replaced or rewritten (None: no file)."""
    try:
        st = path.stat()
    except FileNotFoundError:
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


def _wait_change(path: Path, before, timeout: float = 120.0) -> bool:
    """Spin until ``path`` is no longer what ``before`` says (True) or ``timeout`` s pass."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if _signature(path) != before:
            return True
        time.sleep(0.0002)
    return False


def _check(stage: Path) -> tuple[int, dict]:
    run = subprocess.run([sys.executable, "-m", "lumitrace.cli", "check", str(stage),
                          "--json"], capture_output=True, text=True, timeout=120)
    return run.returncode, json.loads(run.stdout.strip().splitlines()[-1])


# ------------------------------------------------------------------------------------------
# A save that lands while the service writes its result
# ------------------------------------------------------------------------------------------

def test_saves_timed_into_result_writes_are_never_lost(stage):
    """Each of 40 saves of the stage lands the moment the service commits a result (the
    result layer just replaced, the stage's sublayer step under way): each becomes a
    revision, the last result is of the last save, and ``lumitrace check`` says current."""
    layer = stage.parent / "downlight.lumitrace.usda"
    with Service(stage, *QUICK) as s:
        s.wait_done(0)
        text = stage.read_text()  # with the result sublayer, as a DCC that loaded it saves
        assert FLUX in text
        lost, before = [], _signature(layer)
        for i in range(40):
            if i and lost[-1:] != [i - 1]:  # the last save's result (a rescale) is being
                assert _wait_change(layer, before), f"no result after save {i - 1}"
                time.sleep(DELAYS[i % len(DELAYS)])
            before = _signature(layer)  # written: land in that write
            _save(stage, text.replace(FLUX, f"lumitrace:luminousFlux = {1300 + i}"))
            try:
                # a bound on a failure, not a speed: a loaded machine's watcher is slow
                s.wait_status(lambda st: st["revision"] >= i + 1 - len(lost), timeout=120)
            except TimeoutError:
                lost.append(i)
        assert not lost, f"{len(lost)} of 40 saves never became revisions: {lost}"
        status = s.wait_done(40)
        assert status["revision"] == 40 and status["last_error"] is None
        assert s.client.results()["emitted_lm"] == pytest.approx(1339.0)
        revisions = [e.data for e in s.client.history(0) if e.kind == "revision"]
        assert {r["source"] for r in revisions[1:]} == {"file"}  # a burst's newest is
        assert revisions[-1]["revision"] == 40  # traced, those before it may be skipped
        rc, verdict = _check(stage)
        assert rc == 0 and verdict["status"] == "current", verdict


# ------------------------------------------------------------------------------------------
# A stage that vanishes and comes back
# ------------------------------------------------------------------------------------------

def _outages(stage: Path):
    """Ways for the stage file to go away, each with the way it comes back."""
    text = stage.read_text()
    moved = stage.with_name("downlight.moved.usda")

    def restore() -> None:
        if stage.is_symlink() or stage.exists():
            stage.unlink()
        stage.write_text(text)

    def unreadable() -> None:
        if os.geteuid() == 0:  # permissions do not stop root: a link to nothing does
            stage.unlink()
            stage.symlink_to(stage.with_name("nothing.usda"))
        else:
            stage.chmod(0)

    def readable() -> None:
        if stage.is_symlink():
            restore()
        else:
            stage.chmod(0o644)
    return {
        "deleted": (stage.unlink, restore),
        "renamed": (lambda: stage.rename(moved), lambda: moved.rename(stage)),
        "unreadable": (unreadable, readable),
        "garbage": (lambda: stage.write_text("this is no stage\n"), restore),
    }


def test_a_stage_that_comes_back_is_recovered_without_another_edit(stage):
    """The stage deleted, renamed away, made unreadable or saved as garbage: an ``error``
    event and ``last_error`` (the last revision stays); a delta accepted meanwhile cannot
    be written to the missing stage. Once the stage is back, unchanged, the service reads
    it again by itself: ``last_error`` clears and the newest revision is written."""
    with Service(stage, *QUICK) as s:
        s.wait_done(0)
        for n, (name, (leave, come_back)) in enumerate(_outages(stage).items()):
            seen = s.client.history(0)[-1].id
            leave()
            error = s.wait_event(lambda e: e.id > seen and e.kind == "error")
            assert str(stage) in error.data["message"] or name == "renamed", error.data
            s.client.set(REFLECTOR, SPEC, 0.5 + 0.1 * n)  # its result cannot be sublayered
            s.wait_status(lambda st: st["last_error"] is not None, timeout=30)
            come_back()
            status = s.wait_status(
                lambda st: st["last_error"] is None and st["state"] == "done"
                and st["written_revision"] == st["revision"] and st["written_pictures"],
                timeout=30)
            assert status["revision"] >= 2 * n + 2, (name, status)
            assert s.client.results()["revision"] == status["revision"]


# ------------------------------------------------------------------------------------------
# Restarts: revisions only grow, a resuming client learns of the restart
# ------------------------------------------------------------------------------------------

def _flux(stage: Path, lumens: int) -> None:
    text = stage.read_text()
    old = text[text.index("lumitrace:luminousFlux = "):].split("\n", 1)[0]
    _save(stage, text.replace(old, f"lumitrace:luminousFlux = {lumens}"))


def _first_events(service: Service, last_id: int, n: int = 2) -> list:
    """The first ``n`` events of a stream resumed after ``last_id``."""
    got = []
    for event in service.client.events(last_id=last_id, timeout=30):
        got.append(event)
        if len(got) == n:
            return got
    return got


def test_a_save_at_the_moment_the_service_starts_is_not_lost(stage):
    """A DCC saving the stage as the service comes up, before its file watch is running:
    the watch compares the files with what the service read once it is up, so the save
    becomes revision 1 all the same."""
    for lumens in (1300, 1400):
        with Service(stage, *QUICK) as s:
            base = s.client.status()["revision"]
            _flux(stage, lumens)  # at once: the watch may not be up yet
            status = s.wait_status(lambda st: st["revision"] == base + 1, timeout=30)
            assert status["revision"] == base + 1


def test_revisions_only_grow_across_restarts_and_a_resuming_client_learns_of_them(stage):
    """Revisions by deltas and by files saved on disk, a kill -9, a restart: the counter
    goes on from the last one handed out (file-edit revisions included), a stage edited
    while no service ran starts one revision higher, event ids go on above the old ones,
    and a client resuming with an old ``Last-Event-ID`` first gets a ``gap`` event that
    says the service restarted."""
    with Service(stage, *QUICK) as s:
        s.wait_done(0)
        assert s.client.set(REFLECTOR, SPEC, 0.5)["revision"] == 1
        _flux(stage, 1300)
        s.wait_status(lambda st: st["revision"] == 2)
        assert s.client.set(REFLECTOR, SPEC, 0.6)["revision"] == 3
        _flux(stage, 1400)
        s.wait_done(4)
        last_id = s.client.history(0)[-1].id
        s.proc.kill()
        s.proc.wait(30)
    with Service(stage, *QUICK) as s:
        assert s.client.status()["revision"] == 4  # the same scene: the same revision
        gap, started = _first_events(s, last_id)
        assert gap.kind == "gap" and gap.data["restart"] is True, gap
        assert started.kind == "started" and started.id > last_id, started
        _flux(stage, 1500)
        s.wait_done(5)
        last_id = s.client.history(0)[-1].id
        assert _first_events(s, last_id - 1, 1)[0].id == last_id  # no gap within a run
        rc, _ = s.stop()
        assert rc == 0
    _flux(stage, 1600)  # edited while no service runs: revision 5 is another scene
    with Service(stage, *QUICK) as s:
        status = s.wait_done(6)
        assert status["revision"] == 6
        assert s.client.history(0)[0].id > last_id


# ------------------------------------------------------------------------------------------
# What the service says on stderr; --quiet; --no-sublayer
# ------------------------------------------------------------------------------------------

def _stderr(service: Service, wanted: str, timeout: float = 20.0) -> str:
    """The service's stderr so far, once it holds ``wanted``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        text = "".join(service.stderr)
        if wanted in text:
            return text
        time.sleep(0.05)
    raise AssertionError(f"{wanted!r} never said on stderr:\n" + "".join(service.stderr))


def test_the_service_says_each_event_on_stderr_unless_quiet(stage):
    """One line per event: the revision and its source, the retrace share or the restart
    and why, each result written, done, and errors; ``--quiet`` says nothing."""
    with Service(stage, *QUICK) as s:
        s.wait_done(0)
        s.client.set(REFLECTOR, SPEC, 0.5)
        s.wait_done(1)
        _flux(stage, 1300)
        s.wait_done(2)
        _flux(stage, -5)  # a stage that cannot be traced
        text = _stderr(s, "error: ")
        rc, _ = s.stop()
        assert rc == 0
        text = "".join(s.stderr)
    lines = text.splitlines()
    assert any(" started at revision 0, http://" in line for line in lines), text
    assert any("revision 1 from delta: effect material (" + REFLECTOR in line
               for line in lines), text
    assert any(("revision 1: retraced " in line and " photons (" in line)
               or "revision 1: traced afresh: " in line for line in lines), text
    assert any("revision 2 from file: downlight.usda: effect flux" in line
               for line in lines), text
    assert any("revision 2: written with pictures (" in line for line in lines), text
    assert any("revision 1: done, " in line for line in lines), text
    assert any(" error: " in line and "cannot be traced" in line for line in lines), text
    assert any(" stopping at revision 2" in line for line in lines), text
    assert all(line[:2].isdigit() and line[2] == ":" for line in lines), text
    _flux(stage, 1300)
    with Service(stage, *QUICK, "--quiet") as s:
        s.client.set(REFLECTOR, SPEC, 0.6)
        s.wait_done(3)
        rc, _ = s.stop()
        assert rc == 0 and "".join(s.stderr) == ""


def test_no_sublayer_leaves_the_stage_file_untouched(stage):
    """``serve --no-sublayer``, as ``trace`` has: the results and the result layer are
    written, the stage file is not edited."""
    before = stage.read_bytes()
    with Service(stage, *QUICK, "--no-sublayer", "--quiet") as s:
        s.wait_done(0)
        s.client.set(REFLECTOR, SPEC, 0.5)
        s.wait_done(1)
        assert (stage.parent / "downlight.lumitrace.usda").exists()
        assert stage.read_bytes() == before
        assert s.client.status()["revision"] == 1


def _datasheet_figures(stage: Path) -> dict:
    """The figures (``data-key``: ``data-value``) on the datasheet beside ``stage``."""
    import re
    page = (stage.parent / "downlight.datasheet.html").read_text()
    return {k: json.loads(html.unescape(v)) for k, v in
            re.findall(r'data-key="([^"]+)" data-value="([^"]*)"', page)}


def test_serve_deliverables_writes_the_datasheet_and_gldf_of_each_revision(stage):
    """``serve --deliverables``: each done revision's datasheet and GLDF container are
    written with its pictures; after an edit they hold the new revision's figures, the
    container's photometry is the LDT beside them byte for byte."""
    import zipfile
    with Service(stage, *QUICK, "--deliverables", "--quiet") as s:
        s.wait_done(0)
        before = _datasheet_figures(stage)
        _flux(stage, 2400)  # the stage saved: twice the flux, a flux-only edit
        s.wait_done(1)
        after = _datasheet_figures(stage)
        record = s.client.results()
    assert after["luminous_flux"] == pytest.approx(2.0 * before["luminous_flux"], rel=1e-9)
    assert after["luminous_flux"] == record["photometry"]["luminous_flux"]
    assert after["input_hash"] == record["input_hash"] != before["input_hash"]
    with zipfile.ZipFile(stage.parent / "downlight.gldf") as z:
        ldt = [n for n in z.namelist() if n.endswith(".ldt")]
        assert ldt and z.read(ldt[0]) == (stage.parent / "downlight.ldt").read_bytes()
    assert (stage.parent / "downlight.datasheet.pdf").read_bytes()[:5] == b"%PDF-"


# ------------------------------------------------------------------------------------------
# The edits commands while a service holds the stage
# ------------------------------------------------------------------------------------------

def _edits(action: str, stage: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lumitrace.cli", "edits", action,
                           str(stage)], capture_output=True, text=True, timeout=120)


def test_edits_merge_and_discard_are_refused_while_a_service_holds_the_stage(stage):
    """``edits discard`` and ``edits merge`` while the stage is served would be undone by
    the service's next delta: each exits 2 naming the service's process and port, and
    changes nothing; once the service stops, the merge goes through."""
    edits = stage.parent / "downlight.lumitrace-edits.usda"
    with Service(stage, *QUICK, "--quiet") as s:
        s.wait_done(0)
        s.client.set(REFLECTOR, SPEC, 0.5)
        root, layer = stage.read_bytes(), edits.read_bytes()
        port = s.url.rstrip("/").rsplit(":", 1)[1]
        for action in ("discard", "merge"):
            run = _edits(action, stage)
            lines = run.stderr.strip().splitlines()
            assert run.returncode == 2 and len(lines) == 1, (action, run)
            assert f"process {s.proc.pid}" in lines[0] and f"port {port}" in lines[0], lines
            assert stage.read_bytes() == root and edits.read_bytes() == layer, action
        s.client.set("/Luminaire/LED", "lumitrace:luminousFlux", 1500)
        assert f"float {SPEC} = 0.5" in edits.read_text()  # the first delta is kept
        rc, _ = s.stop()
        assert rc == 0
    run = _edits("merge", stage)
    assert run.returncode == 0, run.stderr
    assert not edits.exists() and f"{SPEC} = 0.5" in stage.read_text()


# ------------------------------------------------------------------------------------------
# A heavy delta
# ------------------------------------------------------------------------------------------

def _post_raw(url: str, raw: bytes, timeout: float = 120.0) -> tuple[int, dict]:
    """POST raw bytes to /deltas; (status, JSON answer), 4xx answers included."""
    req = urllib.request.Request(url.rstrip("/") + "/deltas", data=raw, method="POST",
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def _poll_status(url: str, stop: threading.Event, answers: list[tuple[float, float]]) -> None:
    """GET /status every 20 ms until ``stop``, noting when each request went out and when
    its answer came back."""
    while not stop.is_set():
        start = time.monotonic()
        with urllib.request.urlopen(url.rstrip("/") + "/status", timeout=120) as response:
            response.read()
        answers.append((start, time.monotonic()))
        time.sleep(0.02)


def test_a_7_mib_delta_leaves_status_answering_and_a_larger_one_is_refused(stage):
    """A legal 7 MiB delta (a mesh's points: 200,000 of them, those its faces use kept)
    is accepted while another client polls /status, and /status is answered while it is
    taken: some status request both goes out after the delta and is answered before the
    delta's own answer (an order of events, not a time a loaded machine may exceed). A
    batch of more array values than the documented limit is 422 naming it, nothing
    changed."""
    rng = random.Random(3)
    with Service(stage, *QUICK, "--quiet") as s:
        s.wait_done(0)
        usd = Usd.Stage.Open(str(stage))
        kept = [list(p) for p in usd.GetPrimAtPath("/Luminaire/Reflector")
                .GetAttribute("points").Get()]
        points = kept + [[round(rng.uniform(-60, 60), 6) for _ in range(3)]
                         for _ in range(200_000 - len(kept))]
        raw = json.dumps({"deltas": [{"op": "set", "path": "/Luminaire/Reflector",
                                      "property": "points", "value": points}]}).encode()
        assert 6.5 * 2**20 < len(raw) < 8 * 2**20
        stop, answers = threading.Event(), []
        poller = threading.Thread(target=_poll_status, args=(s.url, stop, answers))
        poller.start()
        try:
            while not answers:  # the poller is running
                time.sleep(0.01)
            sent = time.monotonic()
            code, answer = _post_raw(s.url, raw)
            answered = time.monotonic()
        finally:
            stop.set()
            poller.join(120)
        assert code == 200 and answer["revision"] == 1, answer
        during = [(a, b) for a, b in answers if sent < a and b < answered]
        assert during, (answered - sent, answers[-5:])
        over = {"deltas": [{"op": "set", "path": "/Luminaire/Reflector", "property": "points",
                            "value": [[0, 0, 0]] * (MAX_ARRAY_VALUES // 3 + 1)}]}
        code, answer = _post_raw(s.url, json.dumps(over).encode())
        assert code == 422 and str(MAX_ARRAY_VALUES) in answer["error"], answer
        assert s.client.status()["revision"] == 1


def test_edits_merge_keeps_the_stage_files_comments_and_prim_order(stage):
    """Deltas accepted by a service, then ``edits merge`` once it stops: the .usda file is
    edited as text, only the lines of the properties the deltas set (and a prim they
    added) change; its comments (one on the changed line too), formatting and prim order
    survive, no ``reorder`` is added, and the stage composes with the new values."""
    text = stage.read_text().replace(
        'def Xform "Luminaire" (', '# a comment above the luminaire\ndef Xform "Luminaire" (')
    text = text.replace(f"float {SPEC} = 0.92", f"float {SPEC} = 0.92  # measured 2024")
    stage.write_text(text)
    with Service(stage, *QUICK, "--quiet", "--no-sublayer") as s:
        s.wait_done(0)
        s.client.set(REFLECTOR, SPEC, 0.5)
        s.client.send([{"op": "add", "path": "/Luminaire/Baffle", "type": "Cylinder",
                        "properties": {"radius": 30, "height": 5}}])
        assert s.stop()[0] == 0
    assert stage.read_text() == text  # the service never edits it
    edits = stage.with_name(stage.stem + ".lumitrace-edits.usda").read_text()
    run = _edits("merge", stage)
    assert run.returncode == 0, run.stderr
    merged = stage.read_text()
    # (the edits layer and the merge's warning said, where it was not made as text)
    assert "reorder" not in merged and "# a comment above the luminaire" in merged, \
        edits + run.stderr
    assert "not kept" not in run.stderr
    old, new = text.splitlines(), merged.splitlines()
    changes = [(op, [line.strip() for line in old[i1:i2]], [line.strip() for line in new[j1:j2]])
               for op, i1, i2, j1, j2 in difflib.SequenceMatcher(None, old, new).get_opcodes()
               if op != "equal"]
    assert changes == [
        ("replace", [f"float {SPEC} = 0.92  # measured 2024"], [f"float {SPEC} = 0.5  # measured 2024"]),
        ("insert", [], ["", 'def Cylinder "Baffle"', "{", "double height = 5",
                        "double radius = 30", "}"])], changes
    usd = Usd.Stage.Open(str(stage))
    assert usd.GetPrimAtPath(REFLECTOR).GetAttribute(SPEC).Get() == pytest.approx(0.5)
    order = [p.GetName() for p in usd.GetPrimAtPath("/Luminaire").GetChildren()]
    assert order == ["Materials", "LED", "Board", "Reflector", "Diffuser", "Housing",
                     "Baffle"]
