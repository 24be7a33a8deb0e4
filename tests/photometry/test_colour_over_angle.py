"""Colour over angle: Planckian lights round-trip their CCT through a trace, a neutral
luminaire has its light's colour in every direction, and a coloured result is written as
X, Y, Z channels, a colour table, a diagram and figures in the summary and the layer."""
import json
import shutil
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest
from pxr import Sdf, Usd

from lumitrace.photometry.colour import _ohno2013, cct_duv, colour_over_angle, uv_prime
from lumitrace.run.session import TraceSettings, run
from lumitrace.scene import spectra
from helpers.paths import ROOT
from helpers.stages import add_disk, add_mesh, new_stage, read


@pytest.mark.parametrize("cct", [2700.0, 3000.0, 4000.0, 5000.0, 6500.0])
def test_planckian_lights_round_trip_their_cct_in_every_direction(tmp_path, cct):
    stage = new_stage(tmp_path)
    light = add_disk(stage)
    light.CreateEnableColorTemperatureAttr(True)
    light.CreateColorTemperatureAttr(cct)
    # a grey floor below: light that bounces keeps its colour
    add_mesh(stage, "/Luminaire/Floor", points=[(-1, -1, -0.2), (1, -1, -0.2), (1, 1, -0.2),
                                                (-1, 1, -0.2)])
    scene = read(stage)
    assert scene.colour == "emitters"
    acc = run(scene, TraceSettings(photons=20_000, resolution=8, seed=1)).accumulator
    col = colour_over_angle(acc)
    assert col.total["cct_K"] == pytest.approx(cct, abs=10.0)
    lit = col.xyz[1] > 0
    assert np.nanmax(np.abs(col.cct[lit] - cct)) < 10.0
    assert col.uniformity < 1e-9 and col.noise < 1e-9  # no noise in a neutral luminaire


def test_uv_and_cct_agree_with_colour_science():
    import colour

    xyz = colour.sd_to_XYZ(colour.SDS_ILLUMINANTS["FL2"])
    uvp = uv_prime(np.asarray(xyz))
    assert uvp == pytest.approx(colour.xy_to_Luv_uv(colour.XYZ_to_xy(xyz)), abs=1e-12)
    cct, duv = cct_duv(uvp)
    assert float(cct) == pytest.approx(4224, abs=15)  # FL2's published CCT
    assert np.isnan(cct_duv(np.full((2, 1), np.nan))[0]).all()
    # far from the Planckian locus a colour has no CCT (a saturated green LED), but a Duv
    green = uv_prime(np.asarray(colour.wavelength_to_XYZ(530)))
    cct, duv = cct_duv(green[:, None])
    assert np.isnan(cct[0]) and duv[0] > 0.05


def test_cct_and_duv_are_colour_sciences_ohno_2013_to_the_bit():
    import warnings

    import colour

    rng = np.random.default_rng(4)
    uv = np.stack([rng.uniform(0.12, 0.40, 400), rng.uniform(0.22, 0.38, 400)])
    planckian = np.array([colour.temperature.CCT_to_uv(np.array([t, d]), method="Ohno 2013")
                          for t, d in [(1500, 0.0), (2700, 0.001), (6500, -0.003),
                                       (25000, 0.01), (90000, 0.0)]]).T
    uv = np.concatenate([uv, planckian], axis=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its table-bound notes on far-off points
        want = np.asarray(colour.uv_to_CCT(uv.T, method="Ohno 2013"))
    assert np.array_equal(_ohno2013(uv.T), want)  # the same table, the same arithmetic
    cct, duv = cct_duv(np.stack([uv[0], uv[1] * 1.5]))  # from u'v', as the table has it
    far = np.abs(want[:, 1]) > 0.05
    assert far.sum() > 50 and (~far).sum() > 100  # on, near and far off the locus
    # a last-bit change of v can move a near tie of table rows: 1e-7 of Duv at most
    assert duv == pytest.approx(want[:, 1], abs=1e-7)
    assert cct[~far] == pytest.approx(want[~far, 0], rel=1e-5) and np.isnan(cct[far]).all()


def test_a_luminaire_without_colour_writes_none(tmp_path):
    stage = new_stage(tmp_path)
    add_disk(stage)
    acc = run(read(stage), TraceSettings(photons=5_000, resolution=8)).accumulator
    assert colour_over_angle(acc) is None


def test_a_coloured_result_is_written_with_its_colour(tmp_path):
    stage = tmp_path / "warm_downlight.usda"
    shutil.copy(ROOT / "stages" / "warm_downlight.usda", stage)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "lumitrace.cli", "trace", str(stage), "--photons", "300000",
           "--resolution", "32", "--out", str(out), "--no-sublayer", "--json"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    c = summary["colour"]
    assert 2500 < c["cct_K"] < 3100  # a 3000 K LED, warmed by a champagne reflector
    assert 0 < c["colour_uniformity_duv"] < 0.02 and c["colour_uniformity_noise"] > 0
    table = json.loads((out / "warm_downlight.colour.json").read_text())
    assert table["total"]["cct_K"] == pytest.approx(c["cct_K"])
    assert len(table["gamma"]) == 36 and len(table["c"]) == 24
    # the reflector's light, around nadir, is warmer than the LED's own light at 40 deg
    ring = table["allRound"]["cct"]
    assert ring[0] < ring[8] - 100
    assert (out / "warm_downlight.colour.png").stat().st_size > 10_000
    exr = oiio.ImageInput.open(str(out / "warm_downlight.intensity.exr"))
    names = list(exr.spec().channelnames)
    pixels = exr.read_image(0, 0, 0, len(names), oiio.FLOAT).reshape(-1, len(names))
    exr.close()
    assert {"X", "Y", "Z", "raw.X", "raw.Z"} <= set(names)
    px = {n: pixels[:, names.index(n)].astype(np.float64) for n in names}
    # the filtered colours are weighted means of raw ones: inside their range, no fringes;
    # where sharpening takes a stray photon's texel to 0, its colour goes with it
    dark = px["Y"] == 0
    assert np.all(px["X"][dark] == 0) and np.all(px["Z"][dark] == 0)
    lit = (px["raw.Y"] > 0) & ~dark
    assert lit.sum() > 0.9 * (px["raw.Y"] > 0).sum()
    ratio = px["X"][lit] / px["Y"][lit]
    raw_ratio = px["raw.X"][lit] / px["raw.Y"][lit]
    assert ratio.min() >= raw_ratio.min() - 1e-4 and ratio.max() <= raw_ratio.max() + 1e-4
    layer = Sdf.Layer.FindOrOpen(str(out / "warm_downlight.lumitrace.usda"))
    stage_ = Usd.Stage.Open(layer)
    prim = stage_.GetPrimAtPath("/Luminaire")
    assert prim.GetAttribute("lumitrace:result:cct").Get() == pytest.approx(c["cct_K"])
    assert prim.GetAttribute("lumitrace:result:colourData").Get().path == \
        "./warm_downlight.colour.json"


def test_the_colour_of_a_direction_is_independent_of_the_photon_split(tmp_path):
    from lumitrace.scene import Emitter, Material, Scene

    red = spectra.resample([380, 780], [0.2, 0.9], hold=True)
    tri = np.array([[[-1, -1, -0.5], [1, -1, -0.5], [1, 1, -0.5]],
                    [[-1, -1, -0.5], [1, 1, -0.5], [-1, 1, -0.5]]], float)
    e = Emitter("/L", "sphere", 100.0, np.eye(4), radius=0.01, treat_as_point=True)
    scene = Scene(tri, np.zeros(2, np.int32), np.zeros(2, np.int32),
                  (Material("/M", reflectance_spectrum=tuple(red)),), ("/P",), (e,))
    a = run(scene, TraceSettings(photons=40_000, resolution=8, seed=4, threads=1,
                                 batch_size=40_000)).accumulator
    b = run(scene, TraceSettings(photons=40_000, resolution=8, seed=4, threads=2,
                                 batch_size=3_000)).accumulator
    assert np.array_equal(a.cell_tristimulus(), b.cell_tristimulus())
    assert np.array_equal(a.tristimulus_flux(), b.tristimulus_flux())


def test_a_saturated_light_has_a_colour_but_no_cct(tmp_path):
    from pxr import Gf

    stage = new_stage(tmp_path)
    light = add_disk(stage)
    light.GetPrim().CreateAttribute("lumitrace:spectrum", Sdf.ValueTypeNames.Float2Array).Set(
        [Gf.Vec2f(525, 0.0), Gf.Vec2f(530, 1.0), Gf.Vec2f(535, 0.0)])
    stage.Save()
    path = stage.GetRootLayer().realPath
    cmd = [sys.executable, "-m", "lumitrace.cli", "trace", path, "--photons", "5000",
           "--resolution", "8", "--out", str(tmp_path / "out"), "--no-sublayer",
           "--no-pictures"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "CCT none (Duv beyond 0.05)" in done.stdout
    text = (tmp_path / "out" / "luminaire.colour.json").read_text()
    assert "NaN" not in text  # strict JSON: undefined values are null
    table = json.loads(text)
    assert table["total"]["cct_K"] is None
    assert table["total"]["duv"] > 0.05
