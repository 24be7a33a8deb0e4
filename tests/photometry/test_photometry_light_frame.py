"""The IES-shaped result light sits in the photometric frame in Y-up stages too.

UsdLux IES orientation (ours): vertical angle 0 along the light's local -Z, horizontal angle 0
toward its local +X. The photometric frame: nadir = -upAxis, C0 = +X. So in a Y-up stage the
light's local -Z must point to world -Y and its local +X to world +X (and local +Y, C90, to
world -Z: the right-handed frame with nadir down and C0 along +X).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers.paths import ROOT



def _y_up_disc(tmp_path: Path) -> Path:
    text = (ROOT / "stages" / "reference" / "lambertian_disc.usda").read_text()
    text = text.replace('upAxis = "Z"', 'upAxis = "Y"')
    # the disc emits along its local -Z; turned to emit down the Y axis
    text = text.replace("float inputs:radius = 0.05",
                        "float inputs:radius = 0.05\n"
                        "        float xformOp:rotateX = -90\n"
                        '        uniform token[] xformOpOrder = ["xformOp:rotateX"]')
    path = tmp_path / "disc_y_up.usda"
    path.write_text(text)
    return path


def test_result_light_axes_in_a_y_up_stage(tmp_path):
    from pxr import Gf, Usd, UsdGeom, UsdLux

    from lumitrace.publish.outputs import write_outputs
    from lumitrace.run.session import TraceSettings, run
    from lumitrace.stage.reader import read_stage

    stage_path = _y_up_disc(tmp_path)
    scene = read_stage(stage_path)
    assert scene.up_axis == "Y"
    result = run(scene, TraceSettings(photons=100_000, resolution=16, threads=2))
    written = write_outputs(result, None)
    fig = written
    # (bilinear lookups at res 16 spread ~0.5 % of the flux over the horizon)
    assert fig.downward_flux_fraction == pytest.approx(1.0, abs=1e-2)
    assert fig.peak_gamma < 15.0  # the peak is at nadir, -Y

    stage = Usd.Stage.Open(str(stage_path))
    vset = stage.GetDefaultPrim().GetVariantSets().GetVariantSet("lumitraceRepresentation")
    vset.SetVariantSelection("photometric")
    light = stage.GetPrimAtPath("/Luminaire/lumitracePhotometricLight")
    assert light and light.HasAPI(UsdLux.ShapingAPI)
    m = UsdGeom.Xformable(light).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    axis = lambda v: np.array(m.TransformDir(Gf.Vec3d(*v)))  # noqa: E731
    np.testing.assert_allclose(axis((0, 0, -1)), [0, -1, 0], atol=1e-9)  # gamma 0: nadir
    np.testing.assert_allclose(axis((1, 0, 0)), [1, 0, 0], atol=1e-9)    # C0: +X
    np.testing.assert_allclose(axis((0, 1, 0)), [0, 0, -1], atol=1e-9)   # C90: -Z
    # its emitters are off in that variant, so the light is the only source
    assert not stage.GetPrimAtPath("/Luminaire/Source").IsActive()
    ies = UsdLux.ShapingAPI(light).GetShapingIesFileAttr().Get()
    assert Path(ies.resolvedPath) == Path(written["ies"]).resolve()
