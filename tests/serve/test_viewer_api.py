"""What the live view reads and changes, over HTTP against a real ``lumitrace serve``: the
binary preview and geometry frames, the editable scene, the session's settings (a new
threshold re-filters without retracing, a bad one is refused, pause holds the photons),
and ``--no-viewer``."""
from __future__ import annotations

import json
import shutil
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from helpers.http import call_json as post
from helpers.paths import ROOT
from service_process import Service

from lumitrace.serve.viewer import read_frame
from lumitrace.stage.reader import read_stage

FAST = ("--photons", "150000", "--resolution", "32", "--threads", "2")


def get(url: str):
    with urllib.request.urlopen(url) as r:
        return r.read()


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    stage = tmp_path_factory.mktemp("viewer-api") / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage)
    with Service(stage, *FAST) as service:
        service.wait_done(0)
        yield service


def test_the_geometry_is_the_scene_in_the_photometric_frame(served):
    header, arrays = read_frame(get(served.url + "geometry"))
    scene = read_stage(served.stage)
    assert header["triangles"] == len(scene.triangles) and header["every"] == 1
    assert sum(header["counts"]) * 3 == len(arrays["positions"])
    assert header["parts"] == list(scene.parts)
    # a Z-up stage with an unrotated luminaire: the photometric frame is the stage's
    lo, hi = arrays["positions"].min(axis=0), arrays["positions"].max(axis=0)
    pts = np.asarray(scene.triangles).reshape(-1, 3)
    np.testing.assert_allclose(lo, pts.min(axis=0), atol=1e-6)
    np.testing.assert_allclose(hi, pts.max(axis=0), atol=1e-6)


def test_the_preview_is_the_written_result(served):
    header, arrays = read_frame(get(served.url + "preview"))
    results = served.client.results()
    assert header["photons"] == results["photons"] and header["revision"] == 0
    assert header["figures"]["peak_intensity"] == pytest.approx(
        results["photometry"]["peak_intensity"], rel=1e-12)
    # the map's flux: the lat-long map integrated over the sphere is the escaped flux
    g = np.radians(np.asarray(header["latlong"]["gamma"]))
    c = np.radians(np.asarray(header["latlong"]["c"]))
    cell = np.outer(np.sin(g), np.ones_like(c)) * (g[1] - g[0]) * (c[1] - c[0])
    cell[:, -1] = 0.0  # C 360 repeats C 0
    flux = float((arrays["raw"] * cell).sum())
    assert flux == pytest.approx(results["photometry"]["luminous_flux"], rel=0.05)


def test_the_editable_scene_names_the_prims_a_delta_sets(served):
    scene = json.loads(get(served.url + "scene"))
    names = [p["path"] for p in scene["parts"]]
    assert names == ["/Luminaire/Board", "/Luminaire/Reflector", "/Luminaire/Diffuser",
                     "/Luminaire/Housing"]
    reflector = scene["parts"][1]["materials"][0]
    mat = next(m for m in scene["materials"] if m["path"] == reflector)
    assert mat["scattering"] in scene["scattering_models"]
    assert scene["ranges"]["reflectance"] == [0.0, 1.0]
    assert scene["emitters"][0]["flux"] == pytest.approx(1200.0)
    assert all(m["editable"] == bool(m["path"]) for m in scene["materials"])
    assert mat["editable"]


def test_a_new_threshold_refilters_without_retracing_and_a_bad_one_is_refused(served):
    photons = served.client.status()["photons"]
    before_h, before = read_frame(get(served.url + "preview"))
    status, body = post(served.url + "settings", {"threshold": 0})
    assert status == 200 and body["threshold"] == 0
    after_h, after = read_frame(get(served.url + "preview"))
    assert after_h["photons"] == photons and after_h["threshold"] == 0
    np.testing.assert_array_equal(after["filtered"], after["raw"])  # threshold 0: raw
    assert not np.array_equal(before["filtered"], after["filtered"])
    status, body = post(served.url + "settings", {"threshold": -1})
    assert status == 422 and "threshold" in body["error"]
    status, body = post(served.url + "settings", {"bogus": 1})
    assert status == 422 and "bogus" in body["error"]
    assert json.loads(get(served.url + "settings"))["threshold"] == 0
    assert served.client.status()["photons"] == photons
    post(served.url + "settings", {"threshold": 10000})


def test_pause_holds_the_photons_and_resume_goes_on(served):
    status, _ = post(served.url + "settings", {"paused": True})
    assert status == 200
    status, body = post(served.url + "settings", {"photons": 400000})  # more to trace
    assert status == 200 and body["photons"] == 400000 and body["paused"] is True
    held = served.wait_status(lambda s: s["state"] == "paused")["photons"]
    time.sleep(1.0)
    assert served.client.status()["photons"] == held
    post(served.url + "settings", {"paused": False})
    done = served.wait_status(lambda s: s["state"] == "done" and s["photons"] == 400000)
    assert done["photons"] == 400000


def test_no_viewer_serves_the_api_alone(tmp_path):
    stage = tmp_path / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage)
    with Service(stage, *FAST, "--no-viewer") as service:
        with pytest.raises(urllib.error.HTTPError) as info:
            get(service.url)
        assert info.value.code == 404
        assert service.client.status()["revision"] == 0
