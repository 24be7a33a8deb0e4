"""``lumitrace serve`` as it runs: a real server process on a free loopback port, driven by
the stdlib client and by layer files edited on disk; every delta kind; bad requests; the
service's map equal to a fresh ``lumitrace trace`` of the stage with its edits layer; kill -9
and restart; signals; concurrent clients."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from service_process import Service

from lumitrace.client import ServiceError
from lumitrace.publish.exr import read_intensity_exr
from lumitrace.publish.runs import published_run_ids
from helpers.paths import ROOT
from helpers.renderers import renderers

DEMO = ROOT / "stages" / "downlight.usda"
REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
SPEC = "lumitrace:specularReflectance"
FAST = ("--photons", 40_000, "--resolution", 16, "--threads", 2, "--seed", 5)


@pytest.fixture
def stage(tmp_path) -> Path:
    path = tmp_path / "downlight.usda"
    shutil.copy(DEMO, path)
    return path


def _counts(exr: Path) -> np.ndarray:
    channels, _, _ = read_intensity_exr(exr)
    return channels["count"]


def _events(service, kinds=None, last_id=0):
    """The events the service keeps after ``last_id`` (of ``kinds``)."""
    return [e for e in service.client.history(last_id) if kinds is None or e.kind in kinds]


def test_delta_starts_a_revision_and_its_result_is_written(stage):
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        answer = s.client.set(REFLECTOR, SPEC, 0.5)
        assert answer["revision"] == 1
        assert answer["effect"]["kind"] == "material"
        assert answer["effect"]["materials"] == [REFLECTOR]
        status = s.wait_done(1)
        assert status["photons"] == 40_000 and status["edits_layer"].endswith(
            "downlight.lumitrace-edits.usda")
        results = s.client.results()
        assert results["revision"] == 1 and results["photons"] == 40_000
        assert Path(results["outputs"]["polar_diagram"]).exists()
        # the result layer names the revision; the stage file is untouched but for the
        # result sublayer; the delta lives in the edits layer
        layer = (stage.parent / "downlight.lumitrace.usda").read_text()
        assert '"lumitrace:revision" = "1"' in layer
        edits = (stage.parent / "downlight.lumitrace-edits.usda").read_text()
        assert f"float {SPEC} = 0.5" in edits
        assert stage.read_text().replace("    subLayers = [\n        @./downlight.lumitrace.usda@\n    ]\n", "") \
            == DEMO.read_text()
        rc, out = s.stop()
        assert rc == 0 and "last result written for revision 1" in out


def test_an_edit_saved_on_disk_is_a_revision_and_our_own_writes_are_not(stage):
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        time.sleep(0.5)
        assert s.client.status()["revision"] == 0  # the service's writes changed nothing
        (stage.parent / "notes.txt").write_text("not a layer")
        stage.write_text(stage.read_text().replace("lumitrace:luminousFlux = 1200",
                                                   "lumitrace:luminousFlux = 2400"))
        status = s.wait_status(lambda st: st["revision"] == 1)
        assert status["revision"] == 1
        # the engine's event comes once it takes the revision, after /status counts it
        revision = s.wait_event(lambda e: e.kind == "revision" and e.data["revision"] == 1)
        assert revision.data["source"] == "file"
        assert revision.data["effect"]["kind"] == "flux"  # a rescale: nothing retraced
        assert revision.data["layers"] == [str(stage)]
        s.wait_done(1)
        r = s.client.results()
        assert r["emitted_lm"] == pytest.approx(2400.0)
        assert r["photons"] == 40_000


def test_a_lights_colour_is_a_rescale_and_a_surfaces_colour_a_retrace(stage):
    """Through deltas: a colour temperature on the LED of a luminaire with neutral
    surfaces retraces nothing, yet the result has that colour; a champagne reflector then
    makes photons spectral (a restart), and the result is warmer."""
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        assert s.client.results()["colour"]["cct_K"] is None  # no colour: none written
        answer = s.client.set("/Luminaire/LED", "lumitrace:illuminant", "blackbody 4000")
        assert answer["effect"]["kind"] == "flux"
        s.wait_done(1)
        r = s.client.results()
        assert r["photons"] == 40_000 and r["colour"]["cct_K"] == pytest.approx(4000, abs=10)
        assert r["colour"]["colour_uniformity_duv"] == pytest.approx(0.0, abs=1e-9)
        answer = s.client.set(REFLECTOR, "lumitrace:specularSpectrum",
                              [[400.0, 0.6], [700.0, 0.95]])
        assert answer["effect"]["kind"] == "material"
        s.wait_done(2)
        r = s.client.results()
        assert r["colour"]["cct_K"] < 3950  # the reflector's light is warmer
        assert r["colour"]["colour_uniformity_duv"] > 1e-4
        assert Path(r["outputs"]["colour_data"]).exists()


def _ies(path, half_angle):
    """A rotational IES profile: 1000 cd within ``half_angle`` of the axis, 0 beyond."""
    from lumitrace.photometry.grid import CGammaGrid
    from lumitrace.photometry.lm63 import format_ies

    g = np.arange(0.0, 180.0 + 1e-9, 0.5)
    cd = np.where(g <= half_angle, 1000.0, 0.0)[None, :]
    path.write_text(format_ies(CGammaGrid(np.array([0.0]), g, cd, "rotational"), 1000.0,
                               0.0, 0.0, 0.0, {}))


def test_a_lights_ies_file_saved_on_disk_is_a_revision(stage):
    """The files lights read (IES profiles, ray files) are watched like the layers: a new
    profile retraces that light."""
    _ies(stage.parent / "led.ies", 60.0)
    stage.write_text(stage.read_text().replace(
        'prepend apiSchemas = ["LumitraceEmitterAPI"]\n    )\n    {\n        float inputs:height',
        'prepend apiSchemas = ["LumitraceEmitterAPI", "ShapingAPI"]\n    )\n    {\n'
        '        asset inputs:shaping:ies:file = @./led.ies@\n        float inputs:height'))
    assert "led.ies" in stage.read_text()
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        wide = s.client.results()
        _ies(stage.parent / "led.ies", 10.0)
        s.wait_status(lambda st: st["revision"] == 1)
        # the engine's event comes once it takes the revision, after /status counts it
        revision = s.wait_event(lambda e: e.kind == "revision" and e.data["revision"] == 1)
        assert revision.data["source"] == "file"
        assert revision.data["effect"]["kind"] == "emitter"
        assert revision.data["layers"] == [str(stage.parent / "led.ies")]
        s.wait_done(1)
        narrow = s.client.results()
        # a new light: a new scene hash and the light's photons traced again (behind the
        # opal diffuser the beam's shape shows in the light output ratio, not the peak)
        assert narrow["input_hash"] != wide["input_hash"] and narrow["photons"] == 40_000
        assert narrow["escaped_lm"] != wide["escaped_lm"]


def test_a_half_written_layer_is_retried_and_a_broken_one_reported(stage):
    good = stage.read_text()
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        # a program saving in place: first a truncated file, then the whole new one
        stage.write_text(good[: len(good) // 3])
        time.sleep(0.2)
        stage.write_text(good.replace("lumitrace:roughness = 0.15", "lumitrace:roughness = 0.3"))
        status = s.wait_status(lambda st: st["revision"] == 1)
        assert status["revision"] == 1
        assert not [e for e in _events(s, {"error"})]
        # a file left broken: reported once retries run out, the service keeps serving
        stage.write_text("#usda 1.0\n(\n")
        deadline = time.monotonic() + 20
        errors = []
        while not errors and time.monotonic() < deadline:
            errors = [e for e in _events(s, {"error"}) if "keeping revision 1" in e.data["message"]]
            time.sleep(0.1)
        assert errors and "Expected )" in errors[0].data["message"], \
            [(e.kind, e.data.get("revision"), e.data.get("message")) for e in _events(s)]
        assert s.client.status()["revision"] == 1


def _variant_fragment() -> str:
    return """#usda 1.0
over "Luminaire"
{
    over "Materials"
    {
        over "DiffuserOpal" (
            variants = {
                string grade = "standard"
            }
            prepend variantSets = "grade"
        )
        {
            variantSet "grade" = {
                "standard" {
                    float lumitrace:roughness = 0.3
                }
                "premium" {
                    float lumitrace:roughness = 0.6
                }
            }
        }
    }
}
"""


def test_every_delta_kind(stage):
    with Service(stage, *FAST) as s:
        c = s.client
        kinds = {}
        kinds["set"] = c.set(REFLECTOR, SPEC, 0.7)
        kinds["set input"] = c.set(f"{REFLECTOR}/PreviewSurface", "inputs:diffuseColor",
                                   [0.5, 0.5, 0.5])
        kinds["transform"] = c.transform("/Luminaire/Diffuser", translate=[0, 0, -3])
        kinds["bind"] = c.bind("/Luminaire/Housing", "/Luminaire/Materials/BoardWhite")
        kinds["add"] = c.send([{"op": "add", "path": "/Luminaire/Baffle", "type": "Cylinder",
                                "properties": {"radius": 30.0, "height": 5.0}}])
        kinds["active"] = c.send([{"op": "active", "path": "/Luminaire/Baffle",
                                   "active": False}])
        kinds["remove"] = c.send([{"op": "remove", "path": "/Luminaire/Board"}])
        kinds["layer"] = c.send([{"op": "layer", "usda": _variant_fragment()}])
        kinds["variant"] = c.send([{"op": "variant", "path": "/Luminaire/Materials/DiffuserOpal",
                                    "set": "grade", "selection": "premium"}])
        kinds["flux"] = c.set("/Luminaire/LED", "lumitrace:luminousFlux", 1500.0)
        assert [k["revision"] for k in kinds.values()] == list(range(1, 11))
        effects = {name: k["effect"]["kind"] for name, k in kinds.items()}
        assert effects == {"set": "material", "set input": "none", "transform": "geometry",
                           "bind": "material", "add": "topology", "active": "topology",
                           "remove": "topology", "layer": "material", "variant": "material",
                           "flux": "flux"}
        s.wait_done(10)
        edits = (stage.parent / "downlight.lumitrace-edits.usda").read_text()
        for text in ('def Cylinder "Baffle"', "active = false", 'string grade = "premium"',
                     "xformOp:transform:lumitraceDelta", "lumitrace:luminousFlux = 1500"):
            assert text in edits


def test_the_service_map_equals_a_fresh_trace_with_the_edits(stage, tmp_path):
    """Same seed and photons: the service's counts after a sequence of deltas equal, exactly,
    those of `lumitrace trace --edits` on a copy of the stage and its edits layer."""
    with Service(stage, *FAST) as s:
        s.client.set(REFLECTOR, SPEC, 0.6)
        s.client.transform("/Luminaire/Diffuser", translate=[0, 0, -2], rotate=[0, 0, 15])
        s.client.bind("/Luminaire/Housing", "/Luminaire/Materials/BoardWhite")
        s.wait_done(3)
        last = _events(s)[-1].id
        # after the budget is traced, an edit of a part few photons meet is a retrace
        s.client.bind("/Luminaire/Housing", "/Luminaire/Materials/HousingPaint")
        status = s.wait_done(4)
        served = _counts(stage.parent / "downlight.intensity.exr")
        retraced = [e.data for e in _events(s, {"retrace"}, last_id=last)]
    # the housing's photons only, not all
    assert len(retraced) == 1 and 0 < retraced[0]["photons"] < retraced[0]["of"] == 40_000
    assert retraced[0]["rebuilt_parts"] == []  # a material edit rebuilds no Embree geometry
    frame = ",".join(repr(v) for v in status["tracing_frame"])
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    shutil.copy(DEMO, fresh / "downlight.usda")
    shutil.copy(stage.parent / "downlight.lumitrace-edits.usda", fresh / "edits.usda")
    p = subprocess.run([sys.executable, "-m", "lumitrace.cli", "trace",
                        fresh / "downlight.usda", "--edits", fresh / "edits.usda",
                        "--photons", "40000", "--resolution", "16", "--seed", "5",
                        "--threads", "2", "--no-progress", "--json", "--frame", frame],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    traced = _counts(fresh / "downlight.intensity.exr")
    assert served.sum() > 10_000  # escaped photons of 40,000 (LOR about 0.45)
    np.testing.assert_array_equal(served, traced)


def _post_raw(url: str, body: bytes, headers=None) -> tuple[int, dict]:
    req = urllib.request.Request(url + "deltas", data=body, method="POST",
                                 headers=headers or {"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"{}")


BAD = {
    "malformed JSON": (b'{"deltas": [', 400, "not JSON"),
    "not UTF-8": (b'{"deltas": "\xff"}', 400, "not UTF-8"),
    "no deltas": (b'{"deltas": []}', 422, "should be non-empty"),
    "unknown op": (b'{"deltas": [{"op": "explode", "path": "/Luminaire"}]}', 422,
                   "is not one of"),
    "unknown prim": (json.dumps({"deltas": [{"op": "set", "path": "/Luminaire/Nope",
                                             "property": SPEC, "value": 1}]}).encode(),
                     422, "no prim at this path"),
    "wrong type": (json.dumps({"deltas": [{"op": "set", "path": REFLECTOR, "property": SPEC,
                                           "value": "shiny"}]}).encode(), 422, "got a string"),
    "out of range": (json.dumps({"deltas": [{"op": "set", "path": REFLECTOR, "property": SPEC,
                                             "value": 1.5}]}).encode(), 422, "must be in [0, 1]"),
    "NaN": (b'{"deltas": [{"op": "set", "path": "/Luminaire/LED", "property": '
            b'"lumitrace:luminousFlux", "value": NaN}]}', 400, "not JSON"),
    "negative flux": (json.dumps({"deltas": [{"op": "set", "path": "/Luminaire/LED",
                                              "property": "lumitrace:luminousFlux",
                                              "value": -5}]}).encode(), 422, "luminousFlux"),
    "path traversal": (json.dumps({"deltas": [{"op": "layer", "usda":
                                               "#usda 1.0\n(\n    subLayers = [@../../secret.usda@]\n)\n"}
                                              ]}).encode(), 422, "leaves the stage's folder"),
    "absolute asset": (json.dumps({"deltas": [{"op": "set", "path": "/Luminaire/LED",
                                               "property": "shaping:ies:file", "type": "asset",
                                               "value": "/etc/passwd"}]}).encode(), 422,
                       "leaves the stage's folder"),
    "one bad of two": (json.dumps({"deltas": [
        {"op": "set", "path": REFLECTOR, "property": SPEC, "value": 0.3},
        {"op": "bind", "path": "/Luminaire/Housing", "material": "/Luminaire/LED"}]}).encode(),
        422, "not a Material"),
    "oversized": (b'{"deltas": [{"op": "layer", "usda": "#usda 1.0\\n' + b"#" * (9 << 20)
                  + b'"}]}', 413, "larger than"),
}


def test_bad_requests_get_4xx_and_change_nothing(stage):
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        edits = stage.parent / "downlight.lumitrace-edits.usda"
        before = (stage.read_bytes(), edits.exists())
        answers = {}
        for name, (body, status, words) in BAD.items():
            code, payload = _post_raw(s.url, body)
            answers[name] = code
            assert code == status, (name, payload)
            text = payload["error"] + " ".join(p["why"] for p in payload.get("problems", []))
            assert words in text, (name, payload)
        assert (stage.read_bytes(), edits.exists()) == before
        status = s.client.status()
        assert status["revision"] == 0
        # every problem of a batch is listed, each with where it is
        code, payload = _post_raw(s.url, json.dumps({"deltas": [
            {"op": "set", "path": "/Luminaire/Nope", "property": SPEC, "value": 1},
            {"op": "set", "path": REFLECTOR, "property": SPEC, "value": 7}]}).encode())
        assert code == 422 and [p["where"] for p in payload["problems"]] == [
            "/deltas/0 /Luminaire/Nope", f"/deltas/1 {REFLECTOR}.{SPEC}"]
        assert s.client.set(REFLECTOR, SPEC, 0.4)["revision"] == 1  # still serving


def test_a_token_is_required_when_given_and_off_loopback(stage):
    with Service(stage, *FAST, token="s3cret") as s:
        code, payload = _post_raw(s.url, b'{"deltas": []}')
        assert code == 401 and "bearer token" in payload["error"]
        code, _ = _post_raw(s.url, b"{}", {"Authorization": "Bearer wrong"})
        assert code == 401
        assert s.client.status()["revision"] == 0  # the client sends the token
    p = subprocess.run([sys.executable, "-m", "lumitrace.cli", "serve", stage, "--host",
                        "0.0.0.0", "--port", "0"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and "give --token" in p.stderr


def test_kill_9_and_restart_loses_no_accepted_delta(stage):
    slow = ("--photons", 50_000_000, "--resolution", 16, "--threads", 2)
    with Service(stage, *slow) as s:
        for i, value in enumerate((0.3, 0.4, 0.5), start=1):
            assert s.client.set(REFLECTOR, SPEC, value)["revision"] == i
        s.wait_status(lambda st: st["written_revision"] == 3)
        s.proc.send_signal(signal.SIGKILL)
        s.proc.wait(30)
    ids = published_run_ids(stage.parent, "downlight")
    assert None not in ids.values() and len(set(ids.values())) == 1, ids  # one whole set
    assert not list(stage.parent.glob(".downlight.lumitrace-staging-*")) or True
    with Service(stage, *FAST) as s:
        status = s.client.status()
        assert status["revision"] == 3
        s.wait_done(3)
        edits = (stage.parent / "downlight.lumitrace-edits.usda").read_text()
        assert f"float {SPEC} = 0.5" in edits


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="no renderer on one core")
def test_a_script_s_service_draws_in_the_renderer_it_forked_which_ends_with_it(stage):
    """A service started by a script (standard error not a terminal) forks its renderer
    as it starts; its pictures are drawn and written; killed with SIGKILL, it takes its
    renderer with it (none is left running)."""
    with Service(stage, *FAST) as s:
        kids = renderers(s.proc.pid)
        assert len(kids) == 1, kids
        s.wait_done(0)
        layer = (stage.parent / "downlight.lumitrace.usda").read_text()
        assert "photometricSolid" in layer
        assert (stage.parent / "downlight.solid.png").stat().st_size > 10_000
        assert renderers(s.proc.pid) == kids  # the same renderer drew it and goes on
        s.proc.send_signal(signal.SIGKILL)
        s.proc.wait(30)
    for _ in range(100):
        if not kids & renderers():
            break
        time.sleep(0.05)
    assert not kids & renderers()


def test_sigterm_while_tracing_writes_a_final_result(stage):
    slow = ("--photons", 50_000_000, "--resolution", 16, "--threads", 2)
    with Service(stage, *slow) as s:
        s.wait_status(lambda st: st["written_revision"] == 0 and st["photons"] > 100_000)
        rc, out = s.stop(signal.SIGTERM)
    assert rc == 0 and "last result written for revision 0" in out
    layer = (stage.parent / "downlight.lumitrace.usda").read_text()
    assert "polarDiagram" in layer  # the final write draws the pictures
    ids = published_run_ids(stage.parent, "downlight")
    assert None not in ids.values() and len(set(ids.values())) == 1


def test_a_burst_of_deltas_coalesces(stage):
    """100 deltas posted one after another while the service traces: each is accepted
    with the next revision, the engine takes revisions in increasing order only (never one
    older than one it took), and the last one is traced and written. How many of the burst
    it takes depends on how fast the client is against the engine (a loaded machine spaces
    the deltas out): that it takes only the newest of those accepted while it was busy is
    shown by events in test_engine_superseded's
    test_edits_that_come_while_the_engine_is_busy_coalesce_into_the_newest."""
    with Service(stage, "--photons", 2_000_000, "--resolution", 16, "--threads", 2) as s:
        s.wait_status(lambda st: st["photons"] > 0)
        for i in range(100):
            assert s.client.set(REFLECTOR, SPEC, 0.5 + i * 0.004)["revision"] == i + 1
        status = s.wait_status(lambda st: st["traced_revision"] == 100
                               and st["written_revision"] == 100, timeout=300)
        taken = [e.data["revision"] for e in _events(s, {"revision"})]
        traced = {e.data["revision"] for e in _events(s, {"iteration"})}
    assert status["revision"] == 100
    print("revisions traced in the burst:", len(traced))
    assert taken == sorted(set(taken)) and taken[0] == 0 and taken[-1] == 100, taken
    assert traced <= set(taken) and 100 in traced


def test_concurrent_clients_lose_nothing(stage):
    with Service(stage, *FAST) as s:
        accepted: list[tuple[int, float]] = []
        lock = threading.Lock()

        def client(k):
            for i in range(10):
                value = round(0.1 + 0.01 * (10 * k + i), 4)
                r = s.client.set(REFLECTOR, SPEC, value)
                with lock:
                    accepted.append((r["revision"], value))
                s.client.status()
        threads = [threading.Thread(target=client, args=(k,)) for k in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        revisions = sorted(r for r, _ in accepted)
        assert revisions == list(range(1, 41))
        last_value = max(accepted)[1]
        edits = (stage.parent / "downlight.lumitrace-edits.usda").read_text()
        assert f"float {SPEC} = {last_value:g}" in edits


def test_events_stream_and_resume_after_the_last_id(stage):
    """The server-sent-event stream gives every event in order; reconnecting with
    Last-Event-ID resumes right after it, with nothing lost or repeated."""
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        everything = _events(s)
        assert [e.id for e in everything] == list(range(1, len(everything) + 1))
        assert {"started", "revision", "iteration", "written", "done"} <= \
            {e.kind for e in everything}
        middle = everything[len(everything) // 2].id
        streamed = []
        for e in s.client.events(last_id=middle, timeout=30):
            streamed.append(e)
            if e.id == everything[-1].id:
                break
        assert [(e.id, e.kind, e.data) for e in streamed] == \
            [(e.id, e.kind, e.data) for e in everything[middle:]]
        # a new event reaches a waiting stream
        got = []

        def follow():
            for e in s.client.events(last_id=everything[-1].id, timeout=30):
                got.append(e)
                if e.kind == "revision":
                    return
        t = threading.Thread(target=follow)
        t.start()
        time.sleep(0.5)
        s.client.set(REFLECTOR, SPEC, 0.45)
        t.join(30)
        assert got and got[-1].kind == "revision" and got[-1].data["revision"] == 1


def test_a_bad_request_to_the_client_raises_with_every_problem(stage):
    with Service(stage, *FAST) as s:
        with pytest.raises(ServiceError) as info:
            s.client.send([{"op": "set", "path": "/Luminaire/Nope", "property": SPEC,
                            "value": 1}, {"op": "variant", "path": "/Luminaire",
                                          "set": "x", "selection": "y"}])
        assert info.value.status == 422 and len(info.value.problems) == 2


def test_no_request_crashes_the_service(stage):
    """Random bodies, and random deltas close to valid ones: every answer is a JSON 2xx or
    4xx, never a 5xx; the service keeps serving and its edits layer stays readable."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
    from pxr import Sdf

    json_values = st.recursive(
        st.none() | st.booleans() | st.integers(-10**6, 10**6) |
        st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=20),
        lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8),
                                                                  inner, max_size=4),
        max_leaves=12)
    paths = st.sampled_from(["/Luminaire", "/Luminaire/LED", "/Luminaire/Reflector",
                             REFLECTOR, f"{REFLECTOR}/PreviewSurface", "/Luminaire/Nope",
                             "/Luminaire/Materials", "/"])
    props = st.sampled_from([SPEC, "lumitrace:roughness", "lumitrace:scattering",
                             "lumitrace:luminousFlux", "inputs:diffuseColor", "points",
                             "xformOpOrder", "inputs:width", "visibility", "purpose"])
    ops = st.sampled_from(["set", "transform", "bind", "add", "remove", "active", "variant",
                           "layer"])
    delta = st.fixed_dictionaries({"op": ops, "path": paths}, optional={
        "property": props, "value": json_values, "material": paths, "type": st.sampled_from(
            ["Mesh", "Sphere", "float", "Xform", "bogus"]),
        "active": st.booleans(), "translate": st.lists(st.floats(-1e3, 1e3), min_size=3,
                                                       max_size=3),
        "scale": st.lists(st.floats(-2, 2), min_size=3, max_size=3),
        "set": st.text(max_size=5), "selection": st.text(max_size=5),
        "usda": st.sampled_from(["#usda 1.0\n", "#usda 1.0\nover \"Luminaire\"\n{\n}\n",
                                 "#usda 1.0\n(\n", "nonsense"])})
    bodies = (st.fixed_dictionaries({"deltas": st.lists(delta, min_size=1, max_size=3)})
              .map(lambda b: json.dumps(b).encode())
              | json_values.map(lambda v: json.dumps(v).encode())
              | st.binary(max_size=64))
    with Service(stage, "--photons", 20_000, "--resolution", 8, "--threads", 1) as s:
        codes = []

        @settings(max_examples=120, deadline=None, database=None,
                  suppress_health_check=list(HealthCheck))
        @given(bodies)
        def post(body):
            code, payload = _post_raw(s.url, body)
            codes.append(code)
            assert code in (200, 400, 409, 413, 422), (code, payload, body[:300])
            assert "error" in payload or "revision" in payload
        post()
        assert s.proc.poll() is None and s.client.status()["revision"] >= 0
        edits = stage.parent / "downlight.lumitrace-edits.usda"
        if edits.exists():
            assert Sdf.Layer.OpenAsAnonymous(str(edits)) is not None
        assert 422 in codes and 400 in codes


def test_edits_merge_into_the_stage_or_are_discarded(stage, tmp_path):
    """`lumitrace edits merge` folds the accepted deltas into the root layer (the stage then
    reads as it did with the edits layer over it) and removes the edits layer; `discard`
    removes it and leaves the stage as it was."""
    from lumitrace.delta.edits import open_with_edits
    from lumitrace.stage.reader import read_stage, scene_from_stage

    with Service(stage, *FAST) as s:
        s.client.set(REFLECTOR, SPEC, 0.55)
        s.client.transform("/Luminaire/Diffuser", translate=[0, 0, -1.5])
        s.client.send([{"op": "active", "path": "/Luminaire/Housing", "active": False}])
        s.wait_done(3)
        s.stop()
    edits = stage.parent / "downlight.lumitrace-edits.usda"
    keep = tmp_path / "kept_edits.usda"
    shutil.copy(edits, keep)
    with_edits = scene_from_stage(open_with_edits(stage, keep))
    before = stage.read_bytes()
    p = subprocess.run([sys.executable, "-m", "lumitrace.cli", "edits", "discard", stage],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0 and not edits.exists() and stage.read_bytes() == before
    shutil.copy(keep, edits)
    p = subprocess.run([sys.executable, "-m", "lumitrace.cli", "edits", "merge", stage],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert not edits.exists()
    # a deactivated prim is prim metadata, which a text edit does not carry: USD writes
    # the file, and says so and why
    assert "comments and formatting are not kept" in p.stderr and "prim metadata" in p.stderr
    from pxr import Sdf

    Sdf.Layer.Find(str(stage)).Reload(force=True)  # this process read the stage before
    merged = read_stage(stage)
    assert merged.parts == with_edits.parts and merged.materials == with_edits.materials
    np.testing.assert_array_equal(merged.triangles, with_edits.triangles)
    assert merged.content_hash() == with_edits.content_hash()
    assert "/Luminaire/Housing" not in merged.parts
    text = stage.read_text()
    assert "lumitrace:revision" not in text and "@./downlight.lumitrace.usda@" in text
