"""Physically valid edge cases are results, not errors: a luminaire no light leaves, a run of
one or two photons, most of the flux cut by the depth limit. Driven through the real CLI."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from stress_cases import add_mesh, add_sphere_light, box, new_stage

from lumitrace.publish.exr import read_exr_metadata
from helpers.paths import ROOT

ISOTROPIC = ROOT / "stages" / "reference" / "isotropic.usda"


def _trace(stage, out, *extra):
    p = subprocess.run([sys.executable, "-m", "lumitrace.cli", "trace", str(stage),
                        "--out", str(out), "--resolution", "16", "--threads", "1",
                        "--no-progress", "--json", *map(str, extra)],
                       capture_output=True, text=True, timeout=300)
    return p.returncode, (json.loads(p.stdout) if p.returncode in (0, 3) else None), p.stderr


def _closed_box(path: Path, reflectance: float) -> Path:
    stage = new_stage(path)
    add_sphere_light(stage, "/Luminaire/Bulb", 0.01, translate=(0.1, 0.05, 0.02))
    p, f = box((-0.3, -0.2, -0.25), (0.35, 0.3, 0.2), inward=True)
    add_mesh(stage, "/Luminaire/Box", p, f, 1.0, "diffuse", reflectance=reflectance)
    stage.GetRootLayer().Save()
    return path


def test_no_light_escapes_is_a_result(tmp_path):
    """A source in a closed black box: every output is written, the light output ratio is 0,
    the relative error is undefined (null in JSON, absent from no file), exit status 0."""
    stage = _closed_box(tmp_path / "black_box.usda", reflectance=0.0)
    rc, summary, err = _trace(stage, tmp_path / "out", "--photons", 20_000)
    assert rc == 0, err
    assert summary["escaped_lm"] == 0.0 and summary["light_output_ratio"] == 0.0
    assert summary["emitted_lm"] == pytest.approx(1000.0)
    assert summary["relative_error"] is None and summary["converged"] is False
    meta = read_exr_metadata(summary["outputs"]["intensity_map"])
    assert meta["relativeError"] is None and meta["lightOutputRatio"] == 0.0
    ies = Path(summary["outputs"]["ies"]).read_text()
    assert "TILT=NONE" in ies
    assert "no light escapes" in _summary_text_of(stage, tmp_path / "out2")


def _summary_text_of(stage, out) -> str:
    p = subprocess.run([sys.executable, "-m", "lumitrace.cli", "trace", str(stage), "--out",
                        str(out), "--resolution", "8", "--threads", "1", "--no-progress",
                        "--photons", "5000"], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    return p.stdout


def test_no_light_escapes_stops_an_error_target(tmp_path):
    """With only a target error, a luminaire no light leaves would trace forever: the
    session stops after NO_ESCAPE_PHOTONS with a warning saying why, and the target it
    could not reach gives exit status 3 (the outputs are written)."""
    from lumitrace.run.session import NO_ESCAPE_PHOTONS

    stage = _closed_box(tmp_path / "black_box.usda", reflectance=0.0)
    rc, summary, err = _trace(stage, tmp_path / "out", "--target-error", 0.05)
    assert rc == 3, err
    assert summary["target_reached"] is False
    assert any("no light escaped" in w for w in summary["warnings"])  # --json lists them
    assert NO_ESCAPE_PHOTONS <= summary["photons"] < 4 * NO_ESCAPE_PHOTONS
    assert "no light escaped the luminaire" in err


@pytest.mark.parametrize("photons", [1, 2])
def test_one_or_two_photons_are_a_result(tmp_path, photons):
    stage = tmp_path / "isotropic.usda"
    shutil.copy(ISOTROPIC, stage)
    rc, summary, err = _trace(stage, tmp_path / "out", "--photons", photons)
    assert rc == 0, err
    assert summary["photons"] == photons
    # one photon says nothing about its own spread; two photons in two texels give a
    # raw error estimate of exactly 1 (each texel count 1 of 2: variance equals signal)
    if photons == 1:
        assert summary["raw_relative_error"] is None
    else:
        assert summary["raw_relative_error"] == pytest.approx(1.0)
    assert Path(summary["outputs"]["ies"]).exists() and Path(summary["outputs"]["ldt"]).exists()


def test_depth_cut_is_a_warning(tmp_path):
    """A closed white box: every photon bounces until the depth limit; the run says that
    the flux was cut, by how much, and still writes its result."""
    stage = _closed_box(tmp_path / "white_box.usda", reflectance=1.0)
    rc, summary, err = _trace(stage, tmp_path / "out", "--photons", 5_000, "--max-depth", 8)
    assert rc == 0, err
    assert summary["cut_lm"] == pytest.approx(summary["emitted_lm"])
    assert "100.0% of the emitted flux was cut by the depth limit (8 bounces)" in err


def test_parts_no_photon_reaches_are_reported(tmp_path):
    """A driver box on top of the demo's closed housing: no photon can reach it (escaped
    photons never come back), and the run says so, naming it."""
    from pxr import Usd

    stage_path = tmp_path / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage_path)
    stage = Usd.Stage.Open(str(stage_path))
    p, f = box((-0.01, -0.01, 0.08), (0.01, 0.01, 0.09))
    add_mesh(stage, "/Luminaire/Driver", p, f, 0.001, "diffuse", reflectance=0.5)
    stage.GetRootLayer().Save()
    rc, summary, err = _trace(stage_path, tmp_path / "out", "--photons", 50_000)
    assert rc == 0, err
    assert "1 part(s) no traced photon reached: /Luminaire/Driver" in err
    iso = tmp_path / "isotropic.usda"
    shutil.copy(ISOTROPIC, iso)
    rc, summary, err = _trace(iso, tmp_path / "out2", "--photons", 1000)
    assert "no traced photon reached" not in err
