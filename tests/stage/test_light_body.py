"""A light's own body (lumitrace:body): its surface is geometry of the material bound to the
light. A black disk light over a mirror absorbs exactly the light the mirror sends back onto
it (checked against an independent sampling of the same geometry); without the option, or
with a point light, the light is no geometry."""
import math

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdShade

from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.lights import BODY_SEGMENTS
from lumitrace.stage.reader import read_stage

R, H, W = 0.01, 0.01, 0.2  # disk radius, mirror depth below it, mirror half width (m)


def _material(stage, name, scattering, **props):
    mat = UsdShade.Material.Define(stage, f"/Luminaire/Materials/{name}")
    prim = mat.GetPrim()
    prim.AddAppliedSchema("LumitraceMaterialAPI")
    prim.CreateAttribute("lumitrace:scattering", Sdf.ValueTypeNames.Token).Set(scattering)
    for key, value in props.items():
        prim.CreateAttribute(f"lumitrace:{key}", Sdf.ValueTypeNames.Float).Set(value)
    return mat


def _stage(path, body=True, light_kind="disk"):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(root.GetPrim())
    if light_kind == "disk":
        light = UsdLux.DiskLight.Define(stage, "/Luminaire/LED")
        light.CreateRadiusAttr(R)
    else:
        light = UsdLux.SphereLight.Define(stage, "/Luminaire/LED")
        light.CreateTreatAsPointAttr(True)
    p = light.GetPrim()
    p.AddAppliedSchema("LumitraceEmitterAPI")
    p.CreateAttribute("lumitrace:luminousFlux", Sdf.ValueTypeNames.Float).Set(100.0)
    if body:
        p.CreateAttribute("lumitrace:body", Sdf.ValueTypeNames.Bool).Set(True)
    UsdShade.MaterialBindingAPI.Apply(p).Bind(_material(stage, "Black", "absorber"))
    plate = UsdGeom.Mesh.Define(stage, "/Luminaire/Mirror")
    plate.CreatePointsAttr([(-W, -W, -H), (W, -W, -H), (W, W, -H), (-W, W, -H)])
    plate.CreateFaceVertexCountsAttr([4])
    plate.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    UsdShade.MaterialBindingAPI.Apply(plate.GetPrim()).Bind(
        _material(stage, "Mirror", "mirror", specularReflectance=1.0))
    stage.Save()
    return path


def _returned_fraction(n=4_000_000, seed=9):
    """Sampled independently: the share of a Lambertian disk's light that the mirror sends
    back into the disk's inscribed polygon."""
    r = np.random.default_rng(seed)
    rad, phi = R * np.sqrt(r.random(n)), 2 * np.pi * r.random(n)
    p = np.c_[rad * np.cos(phi), rad * np.sin(phi)]
    u, v = r.random(n), 2 * np.pi * r.random(n)
    d = np.c_[np.sqrt(u) * np.cos(v), np.sqrt(u) * np.sin(v)]
    dz = np.sqrt(1 - u)
    on_plate = np.all(np.abs(p + H * d / dz[:, None]) <= W, axis=1)
    back = p + 2 * H * d / dz[:, None]
    rb, pb = np.hypot(back[:, 0], back[:, 1]), np.arctan2(back[:, 1], back[:, 0])
    k = 2 * np.pi / BODY_SEGMENTS
    inside = rb * np.cos(np.mod(pb, k) - k / 2) <= R * np.cos(k / 2)
    return float(np.mean(on_plate & inside))


def test_a_black_light_body_absorbs_what_the_mirror_sends_back(tmp_path):
    scene = read_stage(_stage(tmp_path / "body.usda"))
    assert "/Luminaire/LED" in scene.parts
    photons = 400_000
    acc = run(scene, TraceSettings(photons=photons, resolution=8, seed=4)).accumulator
    f = acc.fluxes()
    absorbed = f["absorbed"] / f["emitted"]
    want = _returned_fraction()
    assert abs(absorbed - want) < 4 * math.sqrt(want * (1 - want) / photons) + 1e-3, \
        (absorbed, want)
    assert want > 0.1  # a test that can fail: a sixth of the light comes back


def test_without_the_option_the_light_is_no_geometry(tmp_path):
    scene = read_stage(_stage(tmp_path / "none.usda", body=False))
    assert "/Luminaire/LED" not in scene.parts
    acc = run(scene, TraceSettings(photons=50_000, resolution=8, seed=4)).accumulator
    assert acc.fluxes()["absorbed"] == 0.0


def test_a_point_light_has_no_body(tmp_path):
    scene = read_stage(_stage(tmp_path / "point.usda", light_kind="point"))
    assert "/Luminaire/LED" not in scene.parts
    assert any("a point light has no body" in w for w in scene.warnings)


@pytest.mark.parametrize("kind,dims", [("rect", {"width": 2.0, "height": 1.0}),
                                       ("sphere", {"radius": 1.0}),
                                       ("cylinder", {"radius": 1.0, "length": 3.0})])
def test_body_surfaces_have_the_lights_area(kind, dims):
    from lumitrace.stage.lights import body_triangles

    t = body_triangles(kind, dims)
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
    want = {"rect": 2.0, "sphere": 4 * math.pi, "cylinder": 2 * math.pi * 3 + 2 * math.pi}[kind]
    assert area == pytest.approx(want, rel=0.01)
