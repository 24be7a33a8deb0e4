"""What the live view compares with and follows, over HTTP against a real ``lumitrace serve``:
each recent revision's last preview kept (``/revisions``), a target file made into a frame
(``POST /reference``: our own IES read back gives our figures), bad requests refused with a
4xx naming what is wrong, the parts' transforms in ``/scene``, the event stream from now or
from a revision (the client's ``events(since=..., revision=...)``), and the client example
of ``docs/live-view.md`` run as it is written."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import threading
import urllib.error
import urllib.request

import pytest
from helpers.paths import ROOT
from service_process import Service

from lumitrace.serve.viewer import read_frame

FAST = ("--photons", "60000", "--resolution", "32", "--threads", "2")
REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    stage = tmp_path_factory.mktemp("compare-api") / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage)
    with Service(stage, *FAST) as service:
        service.wait_done(0, pictures=False)
        yield service


def _get(url: str) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(url) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def _post(url: str, body: bytes) -> tuple[int, bytes]:
    req = urllib.request.Request(url, body, method="POST",
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def test_each_revisions_last_preview_is_kept(served):
    first = json.loads(_get(served.url + "revisions")[1])["revisions"]
    assert [r["revision"] for r in first] == [0] and first[0]["photons"] == 60000
    kept = read_frame(_get(served.url + "revisions/0/preview")[1])
    assert _get(served.url + "revisions/0/preview")[1] == _get(served.url + "preview")[1]
    revision = served.client.set(REFLECTOR, "lumitrace:specularReflectance", 0.7)["revision"]
    served.wait_done(revision, pictures=False)
    _get(served.url + "preview")
    listed = json.loads(_get(served.url + "revisions")[1])["revisions"]
    assert [r["revision"] for r in listed][:2] == [revision, 0]  # newest first
    # revision 0's frame is the one it ended with, unchanged by the edit after it
    assert read_frame(_get(served.url + "revisions/0/preview")[1])[0] == kept[0]
    header, _ = read_frame(_get(served.url + f"revisions/{revision}/preview")[1])
    assert header["revision"] == revision and header["photons"] == 60000
    assert header["figures"]["ugr_4h8h_70_50_20"] > 0
    for path, status in (("revisions/99/preview", 404), ("revisions/x/preview", 400)):
        code, body = _get(served.url + path)
        assert code == status and json.loads(body)["error"]


def test_our_own_ies_read_back_as_a_target_gives_our_figures(served):
    results = served.client.results()
    text = open(results["outputs"]["ies"], encoding="latin-1").read()
    code, body = _post(served.url + "reference",
                       json.dumps({"name": "ours.ies", "text": text}).encode())
    assert code == 200
    header, arrays = read_frame(body)
    assert header["kind"] == "file" and header["name"] == "ours.ies"
    assert header["format"] == "ies" and arrays["filtered"].shape == (91, 181)
    assert (arrays["sigma"] == 0).all()
    ours, theirs = results["photometry"], header["figures"]
    assert theirs["luminous_flux"] == pytest.approx(ours["luminous_flux"], rel=2e-3)
    assert theirs["light_output_ratio"] == pytest.approx(results["light_output_ratio"],
                                                         rel=2e-3)
    # (beam and field angles: read off the file's largest value, which a grid as noisy as
    # this one's, 60,000 photons, puts on a spike; their closed forms are tested on a
    # smooth file in tests/photometry/test_target.py)
    assert theirs["ugr_4h8h_70_50_20"] == pytest.approx(ours["ugr_4h8h_70_50_20"], abs=0.05)


@pytest.mark.parametrize("body, status, said", [
    (b"{not json", 400, "not JSON"),
    (json.dumps({"name": "a.ies", "text": 3}).encode(), 400, "strings"),
    (json.dumps({"name": "a.ies", "text": "IES:LM-63-2019\nTILT=NONE\n1 2"}).encode(), 422,
     "a.ies"),
    (json.dumps({"name": "b.ldt", "text": "x\n" * 40}).encode(), 422, "b.ldt"),
])
def test_a_reference_that_is_not_a_file_is_refused_saying_why(served, body, status, said):
    code, answer = _post(served.url + "reference", body)
    assert code == status and said in json.loads(answer)["error"]


def test_a_reference_follows_the_services_rules_for_what_changes_state(served):
    """POST /reference changes nothing, but is a POST: JSON only, and from a web page only
    with the page's key (the guard's rules for every unsafe request)."""
    text = json.dumps({"name": "a.ies", "text": "x"}).encode()
    for headers, status in (({"Content-Type": "text/plain"}, 415),
                            ({"Content-Type": "application/json",
                              "Origin": served.url.rstrip("/")}, 403)):
        req = urllib.request.Request(served.url + "reference", text, method="POST",
                                     headers=headers)
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(req)
        assert err.value.code == status


def test_the_scene_has_each_parts_local_transform(served):
    scene = json.loads(_get(served.url + "scene")[1])
    for part in scene["parts"]:
        t = part["transform"]
        assert t["editable"] and (t["translate"], t["rotate"], t["scale"]) == \
            ([0.0] * 3, [0.0] * 3, [1.0] * 3)


def _first(events, kinds=None):
    for event in events:
        if kinds is None or event.kind in kinds:
            return event


def test_events_follow_from_now_or_from_a_revision(served):
    history = served.client.history()
    assert history and history[0].kind == "started"  # what events() alone replays first
    newest = history[-1].id
    got: dict = {}
    listening = threading.Event()

    def follow():
        stream = served.client.events(since="now", timeout=60)
        listening.set()
        # the first that carries a revision (a warning of an earlier write may come
        # first), and every one before it
        got["before"] = []
        for event in stream:
            if "revision" in event.data:
                got["now"] = event
                break
            got["before"].append(event)

    t = threading.Thread(target=follow)
    t.start()
    listening.wait(10)
    # the stream is open once the service has answered it: wait for that on its side
    answer = None
    for _ in range(50):
        answer = served.client.set(REFLECTOR, "lumitrace:roughness", 0.1)
        t.join(0.2)
        if "now" in got:
            break
    t.join(60)
    first = got["now"]
    assert first.id > newest and first.data.get("revision", 0) >= 1
    assert all(e.id > newest for e in got["before"])
    revision = answer["revision"]
    served.wait_done(revision, pictures=False)
    from_rev = served.client.events(revision=revision, timeout=60)
    event = next(from_rev)
    assert event.kind == "revision" and event.data["revision"] == revision
    assert served.client.wait_written(revision).data["revision"] >= revision
    assert _get(served.url + "events?since=later")[0] == 400
    assert _get(served.url + "events?revision=x")[0] == 400


def test_the_documented_client_example_runs(served):
    from helpers.doc_examples import blocks

    found = [b.text for b in blocks(ROOT / "docs" / "live-view.md")
             if b.lang == "python" and "c.events(revision=revision)" in b.text]
    assert len(found) == 1, "the client example that follows a revision, in docs/live-view.md"
    code = found[0].replace("http://127.0.0.1:8650", served.url.rstrip("/"))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=180)
    assert r.returncode == 0, r.stderr
    revision = served.client.status()["revision"]
    assert f"revision {revision}: files" in r.stdout and "converged" in r.stdout
