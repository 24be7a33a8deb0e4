"""A fit started from the live view, over HTTP against a real ``lumitrace serve``: the
mirror cup served at reflectance 0.7 (an edit of the session, not the stage file), its
own LDT traced at 0.95 uploaded as the target; the fit runs in its own process, publishes
``fit`` events with its merit, shows the best's curves against the target's, recovers the
reflectance, and its best applied is one delta (a revision whose edits layer holds the
value, the stage file untouched). Bad requests are 4xx naming what is wrong, before
anything starts; a second fit while one runs is 409; Stop ends a fit with its best so far
confirmed."""
from __future__ import annotations

import json
import urllib.error
import urllib.request

import pytest
from helpers.fit_stages import mirror_cup, mirror_cup_target
from helpers.http import call_json as _call
from service_process import Service

from pxr import Sdf

FAST = ("--photons", "40000", "--resolution", "32", "--threads", "2")
MIRROR = "/Luminaire/Materials/Mirror"
REFLECTANCE = f"{MIRROR}.lumitrace:specularReflectance"


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    root = tmp_path_factory.mktemp("live-fit")
    ldt = mirror_cup_target(root)
    stage = mirror_cup(root / "cup.usda", 0.95)
    with Service(stage, *FAST, "--out", root / "out") as service:
        service.wait_done(0, pictures=False)
        revision = service.client.set(MIRROR, "lumitrace:specularReflectance", 0.7)[
            "revision"]
        service.wait_done(revision, pictures=False)
        before = stage.read_bytes()  # (its result layer sublayered by the service)
        yield service, ldt.read_text(encoding="latin-1"), stage, before


def _wait_fit(service, number: int, states=("done", "failed")):
    event = service.wait_event(lambda e: e.kind == "fit" and e.data["fit"] == number
                               and e.data["state"] in states, timeout=300)
    return event.data


def test_bad_fit_requests_are_refused_naming_what_is_wrong(served):
    service, target, *_ = served
    good = {"target": {"name": "t.ldt", "text": target}, "vary": [f"{REFLECTANCE}=0.5:1"]}
    for body, where in (
            ({**good, "vary": ["/Luminaire/Nothing.lumitrace:reflectance"]}, "Nothing"),
            ({**good, "vary": [f"{MIRROR}.lumitrace:scattering"]}, "scattering"),
            ({**good, "vary": [f"{REFLECTANCE}=0.9:0.1"]}, "0.9"),
            ({**good, "vary": []}, "vary"),
            ({**good, "target": {"name": "t.txt", "text": target}}, ".ies or .ldt"),
            ({**good, "target": {"name": "t.ies", "text": "not a photometric file"}},
             "t.ies"),
            ({**good, "evaluations": 0}, "evaluations"),
            ({**good, "photons": "many"}, "photons"),
            ({**good, "colour": 1}, "colour"),
            ({**good, "target": {"revision": "x"}}, "revision")):
        code, answer = _call(service.url + "fit", body)
        assert code == 422, (body, answer)
        text = answer["error"] + json.dumps(answer["problems"])
        assert where in text, (where, answer)
    # another origin's page cannot start, stop or apply a fit (as it cannot send a delta)
    for path in ("fit", "fit/stop", "fit/apply"):
        req = urllib.request.Request(service.url + path, json.dumps(good).encode(),
                                     method="POST", headers={
                                         "Content-Type": "application/json",
                                         "Origin": "http://127.0.0.1:1", "Sec-Fetch-Site":
                                         "cross-site"})
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(req)
        assert refused.value.code == 403, path
    code, answer = _call(service.url + "fit", {**good, "target": {"revision": 99}})
    assert code == 404 and "revision 99" in answer["error"]
    assert _call(service.url + "fit")[1]["state"] == "idle"  # nothing started
    assert _call(service.url + "fit/apply", {})[0] == 409
    assert _call(service.url + "fit/stop", {})[0] == 409


def test_a_fit_from_the_page_recovers_the_reflectance_and_applies_as_one_delta(served):
    service, target, stage, before = served
    code, started = _call(service.url + "fit", {
        "target": {"name": "truth.ldt", "text": target}, "vary": [f"{REFLECTANCE}=0.5:1"],
        "evaluations": 40, "photons": 16384})
    assert code == 202 and started["state"] == "starting"
    number = started["fit"]
    again = _call(service.url + "fit", {"target": {"name": "truth.ldt", "text": target},
                                        "vary": [f"{REFLECTANCE}=0.5:1"]})
    assert again[0] == 409 or _call(service.url + "fit")[1]["state"] == "done"
    end = _wait_fit(service, number)
    assert end["state"] == "done", _call(service.url + "fit")[1]
    state = _call(service.url + "fit")[1]
    # the merit after each generation, the best's curves against the target's
    history = state["history"]
    assert len(history) >= 3 and history[-1]["evaluations"] >= 40
    assert all(h["merit_error"] > 0 for h in history)
    assert min(h["merit"] for h in history) < history[0]["merit"]
    curves = state["curves"]
    n = len(curves["gamma"])
    for plane in ("0", "90"):
        best, want = curves["planes"][plane]["best"], curves["planes"][plane]["target"]
        assert len(best) == len(want) == n
        # where the target is at least half its top, the best holds as much light as it
        # (each value of a candidate's 16,384 photons is noisy; their sum is not)
        lit = [k for k, v in enumerate(want) if v >= 0.5 * max(want)]
        ratio = sum(best[k] for k in lit) / sum(want[k] for k in lit)
        assert len(lit) > 5 and abs(ratio - 1) < 0.05, ratio
    summary = state["summary"]
    assert summary["best"][REFLECTANCE] == pytest.approx(0.95, abs=0.05)
    assert state["can_apply"] and state["applied"] is None
    # the stage file is never written; applying the best is a revision of the session
    assert stage.read_bytes() == before
    code, applied = _call(service.url + "fit/apply", {})
    assert code == 200 and applied["fit"] == number
    service.wait_done(applied["revision"], pictures=False)
    edits = Sdf.Layer.FindOrOpen(applied["edits_layer"])
    spec = edits.GetAttributeAtPath(REFLECTANCE)
    assert spec.default == pytest.approx(summary["best"][REFLECTANCE], rel=1e-6)
    assert _call(service.url + "fit")[1]["applied"] == applied["revision"]
    # its inverse, sent as the page's Undo sends it, sets the value the fit started from
    undone = service.client.send(applied["inverse"])
    service.wait_done(undone["revision"], pictures=False)
    edits = Sdf.Layer.FindOrOpen(applied["edits_layer"])
    edits.Reload()
    assert edits.GetAttributeAtPath(REFLECTANCE).default == pytest.approx(0.7, rel=1e-6)
    assert stage.read_bytes() == before


def test_a_pinned_revision_is_a_target(served):
    """Revision 0 (the stage's reflectance, 0.95), kept by the live view, as the target
    of a fit started from revision 1 (0.7): its preview written as the target file."""
    service, *_ = served
    code, started = _call(service.url + "fit", {
        "target": {"revision": 0}, "vary": [f"{REFLECTANCE}=0.5:1"], "evaluations": 24,
        "photons": 16384})
    assert code == 202 and started["request"]["target"] == "revision-0.ies"
    end = _wait_fit(service, started["fit"])
    assert end["state"] == "done", _call(service.url + "fit")[1]["error"]
    best = _call(service.url + "fit")[1]["summary"]["best"][REFLECTANCE]
    assert best == pytest.approx(0.95, abs=0.08)  # (a 40,000-photon preview's noise)


def test_stop_ends_the_search_and_confirms_its_best_so_far(served):
    service, target, *_ = served
    code, started = _call(service.url + "fit", {
        "target": {"name": "truth.ldt", "text": target}, "vary": [f"{REFLECTANCE}=0.5:1"],
        "evaluations": 2000, "photons": 16384})
    assert code == 202
    number = started["fit"]
    # stopped once its first generation is told
    service.wait_event(lambda e: e.kind == "fit" and e.data["fit"] == number
                       and e.data.get("evaluations"), timeout=300)
    code, stopping = _call(service.url + "fit/stop", {})
    assert code == 200 and stopping["state"] in ("stopping", "done")
    end = _wait_fit(service, number)
    assert end["state"] == "done"
    summary = _call(service.url + "fit")[1]["summary"]
    assert summary["stopped"] == "stopped" and summary["evaluations"] < 2000


def test_a_fit_ends_when_its_service_is_killed(tmp_path, served):
    """A fit's process follows its service: the service killed (SIGKILL, no clean-up), the
    fit's process is gone too, not left tracing for nobody."""
    import os
    import shutil
    import time

    _, target, stage, _ = served
    copy = tmp_path / "cup.usda"
    shutil.copy(stage, copy)
    with Service(copy, *FAST, "--out", tmp_path / "out") as service:
        code, started = _call(service.url + "fit", {
            "target": {"name": "truth.ldt", "text": target},
            "vary": [f"{REFLECTANCE}=0.5:1"], "evaluations": 2000, "photons": 16384})
        assert code == 202
        service.wait_event(lambda e: e.kind == "fit" and e.data.get("evaluations"),
                           timeout=300)
        children = [int(p) for p in os.listdir("/proc") if p.isdigit()
                    and _parent(int(p)) == service.proc.pid
                    and b"spawn_main" in _cmdline(int(p))]
        assert len(children) == 1
        service.kill()
    deadline = time.monotonic() + 30
    while os.path.exists(f"/proc/{children[0]}") and _state(children[0]) != "Z" \
            and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not os.path.exists(f"/proc/{children[0]}") or _state(children[0]) == "Z"


def _parent(pid: int) -> int | None:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return int(f.read().rsplit(")", 1)[1].split()[1])
    except OSError:
        return None


def _state(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "gone"


def _cmdline(pid: int) -> bytes:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read()
    except OSError:
        return b""


def test_a_new_service_numbers_its_fits_after_the_folders(tmp_path):
    """The fits of an earlier session (``fit-1``, ``fit-7``) are never overwritten: the
    next is ``fit-8``."""
    from lumitrace.serve.fitting import LiveFit

    for name in ("fit-1", "fit-7", "fit-x", "notes"):
        (tmp_path / name).mkdir()
    fit = LiveFit(tmp_path / "s.usda", tmp_path / "s.edits.usda", None, tmp_path,
                  lambda *a, **k: None)
    assert fit.status()["fit"] == 7 and fit.status()["state"] == "idle"
    assert LiveFit(tmp_path / "s.usda", tmp_path / "e.usda", None, tmp_path / "none",
                   lambda *a, **k: None).status()["fit"] == 0
