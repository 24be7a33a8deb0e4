"""The photometric frame turns with the luminaire prim, and the luminous opening is measured
from where the light leaves, not taken from the bounding box."""
from __future__ import annotations

import shutil

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdLux

from lumitrace.photometry.distribution import photometry_of
from lumitrace.publish.outputs import photometric_light, write_outputs
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage
from helpers.paths import STAGES

SETTINGS = TraceSettings(photons=400_000, seed=5, resolution=16)


def _tilted_spot(path, turn: tuple[float, float, float] | None) -> None:
    """A Lambertian disc tilted 40 deg about the luminaire's X (light toward its -Z and +Y),
    in a luminaire prim turned by Euler angles ``turn`` (deg)."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    lum = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(lum.GetPrim())
    if turn is not None:
        lum.AddTranslateOp().Set(Gf.Vec3d(3.0, -2.0, 5.0))
        lum.AddRotateXYZOp().Set(Gf.Vec3f(*turn))
    disk = UsdLux.DiskLight.Define(stage, "/Luminaire/Led")
    disk.CreateRadiusAttr(0.01)
    disk.AddRotateXOp().Set(40.0)
    p = disk.GetPrim()
    p.AddAppliedSchema("LumitraceEmitterAPI")
    from pxr import Sdf
    p.CreateAttribute("lumitrace:luminousFlux", Sdf.ValueTypeNames.Float).Set(1000.0)
    stage.GetRootLayer().Save()


@pytest.mark.parametrize("turn", [(0.0, 0.0, 90.0), (20.0, -30.0, 125.0)])
def test_the_photometric_frame_turns_with_the_luminaire(tmp_path, turn):
    _tilted_spot(tmp_path / "plain.usda", None)
    _tilted_spot(tmp_path / "turned.usda", turn)
    plain, turned = read_stage(tmp_path / "plain.usda"), read_stage(tmp_path / "turned.usda")
    a = photometry_of(plain, run(plain, SETTINGS).accumulator)
    b = photometry_of(turned, run(turned, SETTINGS).accumulator)
    # the same distribution in the luminaire's own frame (other photons: a light samples
    # its directions about its world normal), within the two measurements' errors
    assert a.grid.symmetry == b.grid.symmetry == "C90-C270"
    sigma = np.hypot(a.grid.sigma, b.grid.sigma)
    live = sigma > 0
    z = (a.grid.candela - b.grid.candela)[live] / sigma[live]
    assert np.abs(z).max() < 4.5 and 0.8 < np.var(z) < 1.2, (np.abs(z).max(), np.var(z))
    for f in (a.figures, b.figures):  # the light leans toward the luminaire's +Y: C90
        assert abs(f.peak_c - 90.0) <= 30.0 and 20.0 <= f.peak_gamma <= 60.0
    assert b.figures.luminous_flux == pytest.approx(1000.0)
    # the stand-in light sits at the opening in luminaire space, whatever the turn
    la = photometric_light(plain, a, tmp_path / "x.ies", tmp_path)
    lb = photometric_light(turned, b, tmp_path / "x.ies", tmp_path)
    assert np.allclose(la["position"], lb["position"], atol=2e-3)
    assert la["radius"] == pytest.approx(lb["radius"], rel=0.02)


def test_the_downlight_opening_is_its_diffuser_not_its_flange(tmp_path):
    """The downlight's opal diffuser is 124 mm across, its trim flange 150 mm: the IES and
    LDT carry the diffuser (within the 4.7 mm exit bins), with no luminous height."""
    stage = tmp_path / "downlight.usda"
    shutil.copy(STAGES / "downlight.usda", stage)
    scene = read_stage(stage)
    result = run(scene, TraceSettings(photons=300_000, seed=2, resolution=16))
    record = write_outputs(result, None, pictures=False)
    length, width, height = record["luminous_opening"]
    assert 0.114 <= length <= 0.126 and 0.114 <= width <= 0.126, (length, width)
    assert height == 0.0
    from lumitrace.photometry.lm63 import read_ies
    ies = read_ies(record["ies"])
    # a round opening: LM-63's circle, width = length < 0 (the file holds mm)
    assert ies.length == pytest.approx(-length, abs=5e-4)
    assert ies.width == pytest.approx(-width, abs=5e-4)
