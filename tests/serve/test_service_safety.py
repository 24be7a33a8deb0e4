"""``lumitrace serve`` against hostile or careless clients and a failing engine, each case
on a real server process on a free loopback port: asset paths that resolve outside the
stage's folder, client mistakes answered 4xx in JSON (never 500), one service per stage,
and an engine that reports a revision it cannot trace and keeps serving."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from service_process import Service

from helpers.paths import ROOT

ISOTROPIC = ROOT / "stages" / "reference" / "isotropic.usda"
SOURCE = "/Luminaire/Source"
IES_FILE = "inputs:shaping:ies:file"
FAST = ("--photons", 20_000, "--resolution", 8, "--threads", 1, "--seed", 3)
#: The stage's own expression variables: one leaves the folder, one stays in it.
VARIABLES = ('    expressionVariables = {\n        string OUT = "../outside"\n'
             '        string HERE = "."\n    }\n')


@pytest.fixture
def stage(tmp_path) -> Path:
    """The isotropic reference stage in a folder of its own, with expression variables, a
    good IES profile beside it, and a folder ``outside`` next to that folder."""
    folder = tmp_path / "stage"
    folder.mkdir()
    path = folder / "isotropic.usda"
    path.write_text(ISOTROPIC.read_text().replace("    defaultPrim", VARIABLES +
                                                  "    defaultPrim", 1))
    _ies(folder / "good.ies")
    outside = tmp_path / "outside"
    outside.mkdir()
    _ies(outside / "secret.ies")
    (outside / "secret.usda").write_text('#usda 1.0\nover "Luminaire"\n{\n}\n')
    return path


def _ies(path: Path, half_angle: float = 60.0) -> None:
    """A rotational IES profile: 1000 cd within ``half_angle`` of the axis, 0 beyond."""
    from lumitrace.photometry.grid import CGammaGrid
    from lumitrace.photometry.lm63 import format_ies

    g = np.arange(0.0, 180.0 + 1e-9, 0.5)
    cd = np.where(g <= half_angle, 1000.0, 0.0)[None, :]
    path.write_text(format_ies(CGammaGrid(np.array([0.0]), g, cd, "rotational"), 1000.0,
                               0.0, 0.0, 0.0, {}))


def _request(url: str, body: bytes | None = None, headers=None,
             path: str = "deltas") -> tuple[int, str, bytes]:
    """POST ``body`` (GET without one); (status, content type, body), errors included."""
    req = urllib.request.Request(url + path, data=body, method="POST" if body is not None
                                 else "GET",
                                 headers=headers or {"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, r.headers.get("Content-Type", ""), r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.headers.get("Content-Type", ""), exc.read()


def _post(url: str, deltas: list[dict]) -> tuple[int, dict]:
    code, kind, raw = _request(url, json.dumps({"deltas": deltas}).encode())
    assert kind.startswith("application/json"), (code, kind, raw[:300])
    return code, json.loads(raw)


def _set_ies(value: str) -> dict:
    return {"op": "set", "path": SOURCE, "property": IES_FILE, "type": "asset", "value": value}


def _content(path: Path) -> bytes | None:
    """A file's bytes, None where there is none."""
    return path.read_bytes() if path.exists() else None


def _said(payload: dict) -> str:
    return payload["error"] + " " + " ".join(f"{p['where']} {p['why']}"
                                             for p in payload.get("problems", []))


# ------------------------------------------------------------------------------------------
# Asset paths resolve inside the stage's folder
# ------------------------------------------------------------------------------------------

def _fragment(body: str, header: str = "") -> dict:
    return {"op": "layer", "usda": f"#usda 1.0\n{header}\n{body}"}


def _outside_cases(outside: Path) -> dict[str, dict]:
    """Deltas each naming an asset that resolves outside the stage's folder."""
    source = 'over "Luminaire"\n{\n    over "Source"\n    {\n        asset ' + IES_FILE
    return {
        "absolute expression": _set_ies(f'`"{outside / "secret.ies"}"`'),
        "stage variable": _set_ies('`"${OUT}/secret.ies"`'),
        "variable in a relative path": _set_ies('`"./${OUT}/secret.ies"`'),
        "symlink": _set_ies("./link.ies"),
        "dot-dot": _set_ies("../outside/secret.ies"),
        "search path": _set_ies("secret.ies"),
        "fragment attribute expression": _fragment(
            source + ' = @`"${HERE}/${OUT}/secret.ies"`@\n    }\n}\n'),
        "fragment time sample": _fragment(
            source + '.timeSamples = {\n            1: @`"${OUT}/secret.ies"`@,\n'
            '        }\n    }\n}\n'),
        "fragment sublayer expression": _fragment(
            "", f'(\n    subLayers = [@`"{outside / "secret.usda"}"`@]\n)\n'),
        "fragment reference by variable": _fragment(
            'over "Luminaire" (\n    prepend references = @`"${OUT}/secret.usda"`@\n)\n'
            "{\n}\n"),
    }


def test_asset_paths_resolving_outside_the_stage_folder_are_refused(stage, monkeypatch):
    """What a path resolves to counts, not how it is written: expressions with absolute
    paths or the stage's own variables, symlinks, ``..`` and search paths, in 'set' deltas
    and in layer fragments (attribute values, time samples, sublayers, references). Each
    is a 422 naming the delta and property; nothing is authored; paths inside pass."""
    outside = stage.parent.parent / "outside"
    (stage.parent / "link.ies").symlink_to(outside / "secret.ies")
    monkeypatch.setenv("PXR_AR_DEFAULT_SEARCH_PATH", str(outside))
    edits = stage.parent / "isotropic.lumitrace-edits.usda"
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        before = _content(edits)
        for name, delta in _outside_cases(outside).items():
            code, payload = _post(s.url, [_set_ies("./good.ies"), delta])
            assert code == 422, (name, payload)
            said = _said(payload)
            assert "leaves the stage's folder" in said, (name, payload)
            assert "/deltas/1" in said, (name, payload)
            if delta["op"] == "set":
                assert f"{SOURCE}.{IES_FILE}" in said, (name, payload)
            assert _content(edits) == before, name
        code, payload = _post(s.url, [_fragment("", "(\n    expressionVariables = {\n"
                                                    '        string OUT = "/"\n    }\n)\n')])
        assert code == 422 and "expressionVariables" in _said(payload), payload
        assert s.client.status()["revision"] == 0
        for value in ("./good.ies", '`"${HERE}/good.ies"`', "good.ies"):
            code, payload = _post(s.url, [_set_ies(value)])
            assert code == 200, (value, payload)
        assert s.client.status()["revision"] == 3


def test_an_edits_layer_saved_with_an_outside_asset_is_not_followed(stage):
    """The watcher holds the same rule: an edits layer saved on disk that names a file
    outside the stage's folder is reported as an error and the last revision stays."""
    edits = stage.parent / "isotropic.lumitrace-edits.usda"
    with Service(stage, *FAST) as s:
        assert _post(s.url, [_set_ies("./good.ies")])[0] == 200
        s.wait_done(1)
        text = edits.read_text().replace("@./good.ies@", '@`"${OUT}/secret.ies"`@')
        assert "secret.ies" in text
        edits.write_text(text)
        deadline = time.monotonic() + 20
        errors = []
        while not errors and time.monotonic() < deadline:
            errors = [e for e in s.client.history(0) if e.kind == "error"]
            time.sleep(0.1)
        assert errors and "outside the stage's folder" in errors[0].data["message"], errors
        status = s.client.status()
        assert status["revision"] == 1 and status["traced_revision"] == 1


# ------------------------------------------------------------------------------------------
# A client's mistake is a 4xx JSON answer, never a 500
# ------------------------------------------------------------------------------------------

def _nul_cases() -> dict[str, dict]:
    """Deltas with a NUL character where the service takes a path, a name or a text."""
    return {
        "asset path": _set_ies("./good\x00.ies"),
        "asset path in an array": {"op": "set", "path": SOURCE, "property": "my:assets",
                                   "type": "asset[]", "value": ["./good.ies", "a\x00b"]},
        "prim path": {"op": "set", "path": "/Lumi\x00naire", "property": IES_FILE,
                      "value": "./good.ies"},
        "property": {"op": "set", "path": SOURCE, "property": "my\x00prop", "type": "float",
                     "value": 1.0},
        "string value": {"op": "set", "path": SOURCE, "property": "my:text",
                         "type": "string", "value": "a\x00b"},
        "fragment": _fragment('over "Luminaire"\n{\n    custom string t = "\x00"\n}\n'),
        "fragment asset": _fragment('over "Luminaire"\n{\n    custom asset a = @./\x00.ies@\n'
                                    "}\n"),
    }


def test_client_mistakes_are_4xx_json_never_500(stage):
    """A NUL byte in a path or a text, JSON nested a thousand levels and more, and a
    non-ASCII Authorization header: each answered 4xx with a JSON body naming the problem;
    the service keeps serving and authors nothing."""
    edits = stage.parent / "isotropic.lumitrace-edits.usda"
    with Service(stage, *FAST, token="s3cret") as s:
        auth = {"Content-Type": "application/json", "Authorization": "Bearer s3cret"}
        s.wait_done(0)
        before = _content(edits)
        for name, delta in _nul_cases().items():
            code, kind, raw = _request(s.url, json.dumps({"deltas": [delta]}).encode(), auth)
            assert 400 <= code < 500 and kind.startswith("application/json"), (name, code, raw)
            assert json.loads(raw)["problems"], (name, raw)
        for depth in (1000, 5000, 100_000):
            body = b'{"deltas": [{"op": "set", "path": "/Luminaire", "property": "x", ' \
                   b'"value": ' + b"[" * depth + b"]" * depth + b"}]}"
            code, kind, raw = _request(s.url, body, auth)
            assert code == 400 and kind.startswith("application/json"), (depth, code, raw)
            assert "nested" in json.loads(raw)["error"], raw
        for header in ("Bearer s3crét".encode(), "Bearer \u2603".encode(),
                       "Bearer s3crét".encode("latin-1"), b"Bearer \xff\xfe"):
            code, kind, raw = _raw_header_get(s.url, header)
            assert code == 401 and "application/json" in kind, (header, code, raw)
            assert "bearer token" in json.loads(raw)["error"]
        assert _content(edits) == before and s.proc.poll() is None
        assert s.client.status()["revision"] == 0


def _raw_header_get(url: str, authorization: bytes) -> tuple[int, str, bytes]:
    """GET /status with an Authorization header of these bytes (UTF-8 or not), read back
    as (status, content type, body)."""
    import http.client
    from urllib.parse import urlsplit

    parts = urlsplit(url)
    conn = http.client.HTTPConnection(parts.hostname, parts.port, timeout=30)
    try:
        conn.putrequest("GET", "/status")
        conn.putheader("Authorization", authorization)
        conn.endheaders()
        r = conn.getresponse()
        return r.status, r.getheader("Content-Type", ""), r.read()
    finally:
        conn.close()


# ------------------------------------------------------------------------------------------
# One stage, one service
# ------------------------------------------------------------------------------------------

def _serve(stage: Path, *args) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "lumitrace.cli", "serve", str(stage),
                             "--port", "0", *map(str, (*FAST, *args))],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_a_second_service_on_a_stage_refuses_and_a_killed_ones_lock_is_stale(stage):
    """A second `lumitrace serve` of a stage (by another spelling of its path, too) exits 2
    with one line naming the first service's port and process; once the first is killed
    with SIGKILL, its lock is no obstacle: the next service starts and serves."""
    with Service(stage, *FAST) as first:
        port = first.url.rstrip("/").rsplit(":", 1)[1]
        link = stage.parent.parent / "link.usda"
        link.symlink_to(stage)
        for spelling in (stage, link, stage.parent / ".." / "stage" / stage.name):
            second = _serve(spelling)
            try:
                out, err = second.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                second.kill()
                second.communicate()
                pytest.fail(f"a second service of {spelling} started")
            lines = err.strip().splitlines()
            assert second.returncode == 2 and len(lines) == 1, (second.returncode, err)
            assert f"port {port}" in lines[0] and f"process {first.proc.pid}" in lines[0], \
                lines[0]
            assert "lumitrace: serving" not in out
        assert first.client.status()["revision"] == 0  # the first one serves on
        first.proc.send_signal(signal.SIGKILL)
        first.proc.wait(30)
    with Service(stage, *FAST) as after:
        after.wait_done(0)
        assert after.client.send([_set_ies("./good.ies")])["revision"] == 1
        rc, _ = after.stop()
        assert rc == 0


def test_a_hard_link_to_a_served_stage_is_the_same_stage(stage, tmp_path):
    """The lock is on the file, not its path: a second `lumitrace serve`, and `lumitrace
    edits discard`, of a hard link to the served stage (in its folder and in another one,
    made after the first service rewrote the stage to sublayer its results) exit 2 naming
    the first service; the edits layer stays."""
    with Service(stage, *FAST) as first:
        first.wait_done(0)
        assert "isotropic.lumitrace.usda" in stage.read_text()  # rewritten: sublayered
        assert first.client.send([_set_ies("./good.ies")])["revision"] == 1
        edits = stage.parent / "isotropic.lumitrace-edits.usda"
        kept = edits.read_bytes()
        port = first.url.rstrip("/").rsplit(":", 1)[1]
        elsewhere = tmp_path / "elsewhere"
        elsewhere.mkdir()
        links = (stage.parent / "alias.usda", elsewhere / "isotropic.usda")
        for link in links:
            os.link(stage, link)
            assert os.path.samefile(link, stage)
            second = _serve(link)
            try:
                out, err = second.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                second.kill()
                second.communicate()
                pytest.fail(f"a second service of the hard link {link} started")
            lines = err.strip().splitlines()
            assert second.returncode == 2 and len(lines) == 1, (second.returncode, err)
            assert f"port {port}" in lines[0] and f"process {first.proc.pid}" in lines[0], \
                lines[0]
            assert "same file" in lines[0], lines[0]
            discard = subprocess.run([sys.executable, "-m", "lumitrace.cli", "edits",
                                      "discard", str(link)], capture_output=True, text=True,
                                     timeout=60)
            assert discard.returncode == 2 and f"process {first.proc.pid}" in \
                discard.stderr, discard.stderr
        assert edits.read_bytes() == kept
        assert first.client.status()["revision"] == 1  # the first one serves on


# ------------------------------------------------------------------------------------------
# The engine never dies silently
# ------------------------------------------------------------------------------------------

def _shape(stage: Path, ies: str) -> None:
    """Give the stage's source an IES profile (ShapingAPI) read from ``ies``."""
    text = stage.read_text().replace(
        'prepend apiSchemas = ["LumitraceEmitterAPI"]\n    )\n    {\n',
        'prepend apiSchemas = ["LumitraceEmitterAPI", "ShapingAPI"]\n    )\n    {\n'
        f'        asset inputs:shaping:ies:file = @{ies}@\n', 1)
    assert ies in text
    stage.write_text(text)


def test_a_revision_the_engine_cannot_trace_is_an_error_and_the_next_one_traces(stage):
    """A stage whose light reads a garbage IES profile (as left in the edits layer, or on
    disk, before a restart): the engine reports it as an ``error`` event and in
    ``/status.last_error`` (state ``error``), keeps answering, and traces the next good
    revision, which clears ``last_error``."""
    (stage.parent / "bad.ies").write_text("junk\n")
    _shape(stage, "./bad.ies")
    with Service(stage, *FAST) as s:
        error = s.wait_event(lambda e: e.kind == "error")
        assert error.data["revision"] == 0 and "IES" in error.data["message"], error.data
        status = s.wait_status(lambda st: st["last_error"] is not None, timeout=30)
        assert status["state"] == "error" and "bad.ies" in status["last_error"], status
        assert s.proc.poll() is None
        answer = s.client.send([_set_ies("./good.ies")])
        assert answer["revision"] == 1
        status = s.wait_done(1)
        assert status["last_error"] is None and status["photons"] == 20_000
        assert s.client.results()["revision"] == 1


def test_a_garbage_ies_profile_is_refused_at_the_door_and_the_last_result_stays(stage):
    """A delta adding a light whose IES profile cannot be read is a 422 naming the light
    and property; the profile of a light turned to garbage on disk is an ``error`` event
    while the last good result stays served; the repaired file traces again."""
    (stage.parent / "bad.ies").write_text("junk\n")
    _shape(stage, "./good.ies")
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        good = s.client.results()
        code, payload = _post(s.url, [{
            "op": "add", "path": "/Luminaire/Spot", "type": "DiskLight",
            "apiSchemas": ["ShapingAPI", "LumitraceEmitterAPI"],
            "properties": {"inputs:radius": 0.01, "lumitrace:luminousFlux": 100.0,
                           IES_FILE: "./bad.ies"}}])
        assert code == 422, payload
        said = _said(payload)
        assert "/Luminaire/Spot" in said and IES_FILE in said and "bad.ies" in said, said
        assert s.client.status()["revision"] == 0
        (stage.parent / "good.ies").write_text("IESNA:LM-63-2019\nTILT=NONE\n1 2 3\n")
        error = s.wait_event(lambda e: e.kind == "error")
        assert "cannot be traced" in error.data["message"] and IES_FILE in \
            error.data["message"], error.data
        status = s.client.status()
        assert status["revision"] == 0 and status["written_revision"] == 0
        assert "cannot be traced" in status["last_error"], status
        assert s.client.results()["input_hash"] == good["input_hash"]
        _ies(stage.parent / "good.ies", 30.0)
        s.wait_status(lambda st: st["revision"] == 1)
        status = s.wait_done(1)
        assert status["last_error"] is None
        assert s.client.results()["input_hash"] != good["input_hash"]
