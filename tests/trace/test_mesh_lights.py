"""Mesh lights (UsdLux MeshLightAPI): a mesh emits from its triangles, area-weighted, as a
Lambertian surface from its front faces (both sides when doubleSided): a mesh disc is the
DiskLight of the same size, within the photon noise of both."""
import math

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdLux

from lumitrace.photometry.measured import cell_solid_angle_grid, measure
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage

FLUX = 1000.0
RADIUS = 0.05
GAMMAS = np.arange(0.0, 180.0 + 1e-9, 5.0)


def _stage(path, light):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(root.GetPrim())
    light(stage)
    stage.Save()
    return path


def _mesh_disc(stage, two_sided=False, flux=FLUX, intensity=None, segments=96):
    """A disc of RADIUS in z = 0 whose front faces look down (-Z)."""
    phi = 2 * np.pi * np.arange(segments) / segments
    pts = np.vstack([[0.0, 0.0, 0.0], np.c_[RADIUS * np.cos(phi), RADIUS * np.sin(phi),
                                           np.zeros(segments)]])
    faces = [(0, 1 + (i + 1) % segments, 1 + i) for i in range(segments)]  # clockwise from +Z
    mesh = UsdGeom.Mesh.Define(stage, "/Luminaire/Panel")
    mesh.CreatePointsAttr(pts.tolist())
    mesh.CreateFaceVertexCountsAttr([3] * segments)
    mesh.CreateFaceVertexIndicesAttr([i for f in faces for i in f])
    mesh.CreateDoubleSidedAttr(two_sided)
    prim = mesh.GetPrim()
    UsdLux.MeshLightAPI.Apply(prim)
    if intensity is None:
        prim.CreateAttribute("lumitrace:luminousFlux", Sdf.ValueTypeNames.Float).Set(flux)
    else:
        UsdLux.LightAPI(prim).CreateIntensityAttr(intensity)
    return prim


def _disk_light(stage):
    disk = UsdLux.DiskLight.Define(stage, "/Luminaire/Light")
    disk.CreateRadiusAttr(RADIUS)
    disk.GetPrim().AddAppliedSchema("LumitraceEmitterAPI")
    disk.GetPrim().CreateAttribute("lumitrace:luminousFlux",
                                   Sdf.ValueTypeNames.Float).Set(FLUX)


def _grid(path, seed, photons=800_000):
    scene = read_stage(path)
    r = run(scene, TraceSettings(photons=photons, resolution=16, seed=seed))
    return scene, r, measure(r.accumulator, GAMMAS, 15.0).full()


def test_a_mesh_disc_is_the_disk_light_of_its_size(tmp_path):
    scene, _, mesh = _grid(_stage(tmp_path / "mesh.usda", _mesh_disc), seed=1)
    (e,) = scene.emitters
    assert e.kind == "mesh" and e.flux == FLUX and not e.two_sided
    assert "/Luminaire/Panel" in scene.parts  # the panel is a surface as well
    _, _, disk = _grid(_stage(tmp_path / "disk.usda", _disk_light), seed=2)
    s = np.sqrt(mesh.sigma**2 + disk.sigma**2)
    live = s > 0
    z = (mesh.candela - disk.candela)[live] / s[live]
    assert np.abs(z).max() < 5.0 and abs(np.mean(z)) < 0.2 and 0.6 < np.var(z) < 1.5
    assert np.all(mesh.candela[:, GAMMAS > 92.5] == 0)  # nothing above the front side


def test_a_double_sided_mesh_light_emits_half_its_flux_each_way(tmp_path):
    photons = 400_000
    path = _stage(tmp_path / "two.usda", lambda st: _mesh_disc(st, two_sided=True))
    _, _, grid = _grid(path, seed=3, photons=photons)
    flux = grid.candela * cell_solid_angle_grid(GAMMAS, 15.0)
    down, up = flux[:, GAMMAS < 90].sum(), flux[:, GAMMAS > 90].sum()
    assert abs((down + up) / FLUX - 1.0) < 1e-9 + flux[:, GAMMAS == 90].sum() / FLUX
    assert abs(down / (down + up) - 0.5) < 4 * math.sqrt(0.25 / photons)


@pytest.mark.parametrize("two_sided", [False, True])
def test_a_mesh_lights_flux_from_its_intensity_is_pi_l_a_per_side(tmp_path, two_sided):
    path = _stage(tmp_path / f"nits{int(two_sided)}.usda",
                  lambda st: _mesh_disc(st, two_sided=two_sided, intensity=5000.0))
    (e,) = read_stage(path).emitters
    segments = 96
    area = 0.5 * segments * RADIUS**2 * math.sin(2 * math.pi / segments)
    assert e.flux == pytest.approx(math.pi * 5000.0 * area * (2 if two_sided else 1),
                                   rel=1e-9)
