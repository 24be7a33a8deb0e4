"""The add-on's live link against a real ``lumitrace serve`` on a free loopback port, and
its IES light rendered by Cycles on the CPU."""
from __future__ import annotations

import hashlib
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers.blender import blender_python, run_bpy
from helpers.paths import ROOT, STAGES
from service_process import Service

from lumitrace.publish.exr import read_intensity_exr

DEMO = STAGES / "downlight.usda"
PHOTONS = 40_000
FAST = ("--photons", PHOTONS, "--resolution", 16, "--threads", 2, "--seed", 5, "--no-viewer")
DOCS = ROOT / "docs"


@pytest.fixture(scope="module")
def bpy_python():
    return blender_python()


def _counts(exr: Path) -> np.ndarray:
    channels, _, _ = read_intensity_exr(exr)
    return channels["count"]


def test_a_move_in_blender_is_one_delta_and_the_light_is_the_services_newest_ies(
        bpy_python, tmp_path):
    stage = tmp_path / "downlight.usda"
    shutil.copy(DEMO, stage)
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        report = run_bpy("blender_live_session.py", s.url, stage, "--out", tmp_path,
                         "--photons", PHOTONS, "--render", "96x72", timeout=400)
        # ten moves while dragging sent nothing; the move held still went as one delta
        assert report["drag_answers"] == [False] * 11 + [True]
        move, reflector = report["batches"]
        assert move == [{"op": "transform", "path": "/Luminaire/Diffuser",
                         "matrix": [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0],
                                    [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, -5.0, 1.0]]}]
        assert reflector == [{"op": "set", "path": "/Luminaire/Materials/ReflectorAluminium",
                              "property": "lumitrace:specularReflectance", "value": 0.5}]
        assert report["answer"]["effect"]["kind"] == "geometry"
        assert report["reflector_answer"]["effect"]["kind"] == "material"
        first = report["connected_revision"]
        assert (report["moved_revision"], report["edited_revision"]) == (first + 1, first + 2)
        # the service heard Blender twice: one revision for the drag, one for the reflector
        sent = [e.data for e in s.client.history(0) if e.kind == "revision"
                and e.data["source"] == "delta"]
        assert [r["revision"] for r in sent] == [first + 1, first + 2]
        status = s.wait_done(first + 2)
        assert report["error"] == ""
        # the panel shows the service, revision, photons, error and the key figures
        panel = "\n".join(report["panel"])
        photometry = s.client.results()["photometry"]
        for text in (s.url.rstrip("/"), f"revision {first + 2}", f"light from {first + 2}",
                     f"{PHOTONS:,} photons",
                     f"flux {photometry['luminous_flux']:.1f} ± "
                     f"{photometry['luminous_flux_error']:.1f} lm", "LOR ", "peak "):
            assert text in panel, (text, panel)
        # the Blender light holds the service's newest IES file, of the last revision (a
        # Blender text keeps the file's CRLF line ends as LF)
        ies = (stage.parent / "downlight.ies").read_bytes().replace(b"\r\n", b"\n")
        results = s.client.results()
        assert results["revision"] == report["light_revision"] == first + 2
        assert hashlib.sha256(ies).hexdigest() == report["light_ies_sha256"]
        assert (tmp_path / "light.ies").read_bytes() == ies
        served = _counts(stage.parent / "downlight.intensity.exr")
        edits = (stage.parent / "downlight.lumitrace-edits.usda").read_text()
    # the service's result equals `lumitrace trace` of the same edits, count for count
    assert "xformOp:transform:lumitraceDelta" in edits and \
        "float lumitrace:specularReflectance = 0.5" in edits
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    shutil.copy(DEMO, fresh / "downlight.usda")
    (fresh / "edits.usda").write_text(edits)
    frame = ",".join(repr(v) for v in status["tracing_frame"])
    p = subprocess.run([sys.executable, "-m", "lumitrace.cli", "trace",
                        fresh / "downlight.usda", "--edits", fresh / "edits.usda",
                        "--photons", str(PHOTONS), "--resolution", "16", "--seed", "5",
                        "--threads", "2", "--no-progress", "--no-pictures", "--json",
                        "--frame", frame], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    np.testing.assert_array_equal(served, _counts(fresh / "downlight.intensity.exr"))
    # the light sits at the luminous opening's centre that the result layer gives
    layer = (stage.parent / "downlight.lumitrace.usda").read_text()
    assert "lumitracePhotometricLight" in layer
    # the room lit by the live light: darker after the reflector lost 0.42 of its 0.92
    before, after = report["render_before"], report["render_after"]
    assert 0.02 < after < 0.9 * before < 0.9, (before, after)


def test_the_ies_light_is_calibrated_and_turned_as_the_luminaire(bpy_python, tmp_path):
    """Cycles renders the light's candela as the IES says (a flat 1000 cd profile 2 m above
    a Lambertian floor of albedo 0.8: radiance 0.8 x 1000 / 177.83 / 4 / pi at nadir,
    in a metre and a millimetre scene), C = 0 toward the luminaire's +X and C = 90 toward
    its +Y (the light turned 30 deg about z: the lit patches at 30 and 120 deg)."""
    report = run_bpy("ies_render.py", tmp_path)
    expected = 0.8 * 1000.0 / 177.83 / 4.0 / math.pi
    assert report["radiance_m"] == pytest.approx(expected, rel=0.01)
    assert report["radiance_mm"] == pytest.approx(expected, rel=0.01)
    for name, angle in (("c0", 30.0), ("c90", 120.0)):
        x, y = report[name]
        assert math.degrees(math.atan2(y, x)) == pytest.approx(angle, abs=3.0), name
        assert 0.7 < math.hypot(x, y) < 1.8  # gamma 20-60 deg from 1 m up
