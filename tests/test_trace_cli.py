"""The ``lumitrace trace`` command as a user runs it: outputs, their contents, bad input."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdLux

from lumitrace.publish.exr import read_intensity_exr
from lumitrace.report.references import expected_intensity, read_expectation
from lumitrace.film.texel_quadrature import texel_integrals
from helpers.reference import chi2_pvalue
from helpers.paths import REFERENCE, ROOT



def lumitrace(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lumitrace.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def traced_disc(tmp_path_factory):
    """The Lambertian disc traced through the CLI in a scratch folder."""
    folder = tmp_path_factory.mktemp("disc")
    stage = folder / "disc.usda"
    shutil.copy(REFERENCE / "lambertian_disc.usda", stage)
    out = lumitrace("trace", stage, "--photons", "400000", "--resolution", "16", "--seed", "3",
                    "--json")
    assert out.returncode == 0, out.stderr
    return stage, json.loads(out.stdout.strip().splitlines()[-1])


def test_json_summary(traced_disc):
    stage, summary = traced_disc
    assert summary["photons"] == 400_000
    assert summary["emitted_lm"] == pytest.approx(1000.0)
    assert summary["escaped_lm"] == pytest.approx(1000.0)
    assert summary["absorbed_lm"] == 0.0
    assert summary["light_output_ratio"] == pytest.approx(1.0)
    assert summary["photometry"]["peak_direction"][2] < -0.9  # straight down
    assert Path(summary["outputs"]["intensity_map"]) == stage.with_name("disc.intensity.exr")


def test_result_layer_is_sublayered_once_and_holds_the_figures(traced_disc):
    stage, summary = traced_disc
    layer = Sdf.Layer.FindOrOpen(str(stage))
    assert layer.subLayerPaths.count("./disc.lumitrace.usda") + \
        layer.subLayerPaths.count("disc.lumitrace.usda") == 1
    opened = Usd.Stage.Open(str(stage))
    prim = opened.GetDefaultPrim()
    get = lambda n: prim.GetAttribute(f"lumitrace:result:{n}").Get()  # noqa: E731
    assert get("photons") == 400_000
    assert get("luminousFlux") == pytest.approx(1000.0)
    assert get("resolution") == 16 and get("seed") == 3
    assert get("intensityMap").path.endswith("disc.intensity.exr")
    assert len(get("inputHash")) == 64
    assert get("relativeError") == pytest.approx(summary["relative_error"])


def test_exr_follows_the_cosine_law_in_openexr_cube_layout(traced_disc, imf_probe):
    """Read the EXR back, locate every pixel with OpenEXR's own CubeMap::direction, and
    compare the photon counts with the Lambertian disc's closed form."""
    stage, _ = traced_disc
    channels, meta, header = read_intensity_exr(stage.with_name("disc.intensity.exr"))
    res = channels["Y"].shape[1]
    assert channels["Y"].shape == (6 * res, res) and res == 16
    assert meta["photons"] == 400_000 and meta["resolution"] == 16
    faces, pys, pxs = np.meshgrid(np.arange(6), np.arange(res), np.arange(res), indexing="ij")
    out = imf_probe([f"D {res} {f} {x} {y}" for f, x, y in zip(faces.ravel(), pxs.ravel(), pys.ravel())])
    d = out[:, :3] / np.linalg.norm(out[:, :3], axis=1, keepdims=True)
    col, row = out[:, 3].astype(int), out[:, 4].astype(int)
    y = channels["Y"][row, col]
    count = channels["count"][row, col]
    # nothing above the horizon of a downward one-sided disc, and the cosine law below
    assert np.all(count[d[:, 2] > 1e-6] == 0)
    exp = read_expectation(stage)
    expected = texel_integrals(lambda v: expected_intensity(exp, v), res)[row, col] * 400_000 / 1000.0
    assert chi2_pvalue(count, expected) > 1e-4
    central = count > 1000
    ratio = y[central] / ((1000.0 / np.pi) * -d[central, 2])
    assert np.abs(ratio - 1).max() < 0.2  # texel averages vs centre values, plus noise
    assert np.median(ratio) == pytest.approx(1.0, abs=0.03)


def test_second_run_replaces_results_without_duplicating_the_sublayer(traced_disc):
    stage, _ = traced_disc
    out = lumitrace("trace", stage, "--photons", "50000", "--resolution", "8", "--json")
    assert out.returncode == 0, out.stderr
    layer = Sdf.Layer.FindOrOpen(str(stage))
    layer.Reload(force=True)
    assert sum("disc.lumitrace.usda" in p for p in layer.subLayerPaths) == 1
    opened = Usd.Stage.Open(str(stage))
    assert opened.GetDefaultPrim().GetAttribute("lumitrace:result:photons").Get() == 50_000


# ------------------------------------------------------------------ bad input


def _stage_with(tmp_path: Path, edit) -> Path:
    path = tmp_path / "bad.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", path)
    stage = Usd.Stage.Open(str(path))
    edit(stage)
    stage.GetRootLayer().Save()
    return path


def _assert_clean_failure(out, path: Path, *needles: str):
    assert out.returncode == 2, out.stdout + out.stderr
    assert "Traceback" not in out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("lumitrace: error:"), out.stderr
    for n in needles:
        assert n in lines[0], lines[0]
    folder = path.parent
    assert not list(folder.glob("*.exr")) and not list(folder.glob("*.lumitrace.usda"))


def test_missing_file(tmp_path):
    path = tmp_path / "nope.usda"
    _assert_clean_failure(lumitrace("trace", path), path, "nope.usda")


def test_not_a_usd_file(tmp_path):
    path = tmp_path / "junk.usda"
    path.write_text("this is not a USD layer {{{\n")
    _assert_clean_failure(lumitrace("trace", path), path, "junk.usda")


def test_bytes_that_are_not_utf8(tmp_path):
    """Latin-1 in a comment of the stage, or of a sublayer: one line naming file, line and
    column of the first bad byte (USD's own message cannot even be printed)."""
    bad = tmp_path / "latin1.usda"
    bad.write_bytes((REFERENCE / "isotropic.usda").read_bytes() + b"# caf\xe9\n")
    line = bad.read_bytes().count(b"\n")
    p = lumitrace("trace", bad, "--photons", 1000)
    _assert_clean_failure(p, bad, "latin1.usda", f"line {line}, column 6: byte 0xe9 is not UTF-8")
    root = tmp_path / "root.usda"
    root.write_text('#usda 1.0\n(\n    subLayers = [@./latin1.usda@]\n    defaultPrim = '
                    '"Luminaire"\n)\n')
    p = lumitrace("trace", root, "--photons", 1000)
    _assert_clean_failure(p, root, "latin1.usda", f"line {line}, column 6")


def test_nan_points(tmp_path):
    def edit(stage):
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Luminaire/Reflector"))
        pts = list(mesh.GetPointsAttr().Get())
        pts[3] = (float("nan"), 0.0, 0.0)
        mesh.GetPointsAttr().Set(pts)
    path = _stage_with(tmp_path, edit)
    _assert_clean_failure(lumitrace("trace", path), path, "/Luminaire/Reflector", "points")


def test_unknown_material_token(tmp_path):
    def edit(stage):
        mat = next(p for p in stage.Traverse() if p.HasAttribute("lumitrace:scattering"))
        mat.GetAttribute("lumitrace:scattering").Set("shiny")
        edit.path = str(mat.GetPath())
    path = _stage_with(tmp_path, edit)
    _assert_clean_failure(lumitrace("trace", path), path, edit.path, "lumitrace:scattering",
                          "shiny")


def test_light_without_flux(tmp_path):
    def edit(stage):
        led = stage.GetPrimAtPath("/Luminaire/LED")
        led.RemoveProperty("lumitrace:luminousFlux")
        led.RemoveProperty("inputs:intensity")
        assert UsdLux.RectLight(led)
    path = _stage_with(tmp_path, edit)
    _assert_clean_failure(lumitrace("trace", path), path, "/Luminaire/LED", "flux")


def test_bad_option_value(tmp_path):
    out = lumitrace("trace", ROOT / "stages" / "downlight.usda", "--photons", "-5")
    assert out.returncode == 2 and "positive" in out.stderr
