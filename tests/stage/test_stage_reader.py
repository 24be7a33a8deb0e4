"""Reading luminaire stages into scenes: units, geometry, instancing, materials, emitters
and the errors bad input gets."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest
from numpy.testing import assert_allclose

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)
from lumitrace.errors import StageError
from lumitrace.schema import PLUGIN_PATH_VARIABLE
from lumitrace.stage import (light_flux, luminance, preview_surface_values, read_stage,
                             scene_from_stage, shaping_fraction)
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt

from helpers.stages import QUAD, add_disk, add_mesh, expect_error, new_stage, read  # noqa: F401


def normals(triangles):
    n = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def preview_material(stage, path, **inputs):
    material = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, path + "/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    types = {"diffuseColor": Sdf.ValueTypeNames.Color3f,
             "specularColor": Sdf.ValueTypeNames.Color3f,
             "useSpecularWorkflow": Sdf.ValueTypeNames.Int}
    for name, value in inputs.items():
        shader.CreateInput(name, types.get(name, Sdf.ValueTypeNames.Float)).Set(value)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material


def bind(prim, material):
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)


def material_of(scene, part):
    index = scene.material_index[scene.part_index == scene.parts.index(part)]
    assert np.unique(index).size == 1
    return scene.materials[int(index[0])]


# -- units and axes --------------------------------------------------------------------

def test_millimetres_and_metres_give_the_same_triangles(tmp_path):
    scenes = []
    for name, mpu, scale in (("mm.usda", 0.001, 1000.0), ("m.usda", 1.0, 1.0)):
        stage = new_stage(tmp_path, name, meters_per_unit=mpu)
        part = UsdGeom.Xform.Define(stage, "/Luminaire/Part")
        part.AddTranslateOp().Set(Gf.Vec3d(0.02 * scale, 0.0, 0.1 * scale))
        add_mesh(stage, "/Luminaire/Part/Reflector", scale=0.1 * scale)
        light = add_disk(stage, flux=None, radius=0.05 * scale)
        light.CreateIntensityAttr(1000.0)
        light.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 0.05 * scale))
        scenes.append(read(stage))
    mm, m = scenes
    assert mm.meters_per_unit == pytest.approx(0.001)
    assert_allclose(mm.triangles, m.triangles, atol=1e-12)
    assert_allclose(m.triangles[0], [[0.02, 0, 0.1], [0.12, 0, 0.1], [0.12, 0.1, 0.1]])
    # to_world maps local stage units to metres; the flux uses the world area
    assert_allclose(mm.emitters[0].to_world[:3, 3], [0, 0, 0.05], atol=1e-12)
    assert_allclose(mm.emitters[0].to_world[:3, :3], 0.001 * np.eye(3))
    assert mm.emitters[0].radius == pytest.approx(50.0)
    assert mm.emitters[0].flux == pytest.approx(m.emitters[0].flux, rel=1e-6)
    assert m.emitters[0].flux == pytest.approx(math.pi * 1000.0 * math.pi * 0.05 ** 2)


def test_y_up_stage_keeps_its_axes(tmp_path):
    stage = new_stage(tmp_path, up_axis="Y")
    add_mesh(stage, "/Luminaire/Part")
    add_disk(stage)
    scene = read(stage)
    assert scene.up_axis == "Y"
    assert_allclose(scene.triangles.reshape(-1, 3)[:3], [(0, 0, 0), (1, 0, 0), (1, 1, 0)])


def test_luminaire_and_stage_paths(tmp_path):
    stage = new_stage(tmp_path)
    add_mesh(stage, "/Luminaire/Part")
    add_disk(stage)
    other = UsdGeom.Xform.Define(stage, "/Other")
    add_mesh(stage, "/Other/Part")
    add_disk(stage, "/Other/Led")
    scene = read(stage)
    assert scene.luminaire_path == "/Luminaire"
    assert scene.stage_path == str((tmp_path / "luminaire.usda").resolve())
    assert scene.parts == ("/Luminaire/Part",)
    assert [e.path for e in scene.emitters] == ["/Luminaire/Led"]
    chosen = read_stage(tmp_path / "luminaire.usda", luminaire=str(other.GetPath()))
    assert chosen.luminaire_path == "/Other" and chosen.parts == ("/Other/Part",)


def test_no_default_prim_uses_the_first_root_prim(tmp_path):
    stage = new_stage(tmp_path)
    add_disk(stage)
    stage.ClearDefaultPrim()
    scene = read(stage)
    assert scene.luminaire_path == "/Luminaire"
    assert any("no defaultPrim" in w for w in scene.warnings)


def test_scene_from_an_open_in_memory_stage():
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/Luminaire").GetPrim())
    add_mesh(stage, "/Luminaire/Part")
    add_disk(stage)
    scene = scene_from_stage(stage)
    assert scene.stage_path == ""
    assert_allclose(scene.triangles.reshape(-1, 3).max(axis=0), [0.01, 0.01, 0])


# -- geometry --------------------------------------------------------------------------

def test_polygons_are_fan_triangulated(tmp_path):
    stage = new_stage(tmp_path)
    pentagon = [(math.cos(a), math.sin(a), 0) for a in np.linspace(0, 2 * math.pi, 6)[:-1]]
    add_mesh(stage, "/Luminaire/Quad")
    add_mesh(stage, "/Luminaire/Mixed", points=QUAD + pentagon, counts=(3, 4, 5),
             indices=(0, 1, 2, 0, 1, 2, 3, 4, 5, 6, 7, 8))
    add_disk(stage)
    scene = read(stage)
    parts = [scene.parts[i] for i in scene.part_index]
    assert parts.count("/Luminaire/Quad") == 2
    assert parts.count("/Luminaire/Mixed") == 1 + 2 + 3
    assert_allclose(normals(scene.triangles), np.tile([0, 0, 1.0], (8, 1)), atol=1e-12)
    assert scene.triangles.dtype == np.float64 and scene.triangles.shape == (8, 3, 3)
    assert scene.material_index.dtype == np.int32 and scene.part_index.dtype == np.int32


def test_left_handed_meshes_are_flipped(tmp_path):
    stage = new_stage(tmp_path)
    add_mesh(stage, "/Luminaire/Right")
    add_mesh(stage, "/Luminaire/Left").CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    add_disk(stage)
    scene = read(stage)
    n = normals(scene.triangles)
    right = scene.part_index == scene.parts.index("/Luminaire/Right")
    assert_allclose(n[right], [[0, 0, 1]] * 2, atol=1e-12)
    assert_allclose(n[~right], [[0, 0, -1]] * 2, atol=1e-12)


def test_mirroring_transform_keeps_the_front_face(tmp_path):
    stage = new_stage(tmp_path)
    mesh = add_mesh(stage, "/Luminaire/Part")
    mesh.AddScaleOp().Set(Gf.Vec3f(-1, 1, 1))
    add_disk(stage)
    scene = read(stage)
    # mirrored in x, the surface still faces +z (the mirror image of a +z facing quad)
    assert_allclose(normals(scene.triangles), [[0, 0, 1]] * 2, atol=1e-12)
    assert scene.triangles[..., 0].max() <= 0.0


def test_transforms_are_composed(tmp_path):
    stage = new_stage(tmp_path, meters_per_unit=0.01)
    group = UsdGeom.Xform.Define(stage, "/Luminaire/Group")
    group.AddTranslateOp().Set(Gf.Vec3d(10, 0, 0))
    mesh = add_mesh(stage, "/Luminaire/Group/Part")
    mesh.AddRotateZOp().Set(90.0)
    mesh.AddScaleOp().Set(Gf.Vec3f(2, 2, 2))
    add_disk(stage)
    scene = read(stage)
    # local (1, 0, 0) -> scale 2 -> rotate 90 about z -> (0, 2, 0) -> + (10, 0, 0), in cm
    assert_allclose(scene.triangles[0, 1], [0.10, 0.02, 0.0], atol=1e-12)
    assert_allclose(scene.triangles[0, 0], [0.10, 0.0, 0.0], atol=1e-12)


def test_native_instances_are_traversed(tmp_path):
    stage = new_stage(tmp_path)
    proto = UsdGeom.Xform.Define(stage, "/Prototypes/Fin")
    add_mesh(stage, "/Prototypes/Fin/Blade")
    stage.GetPrimAtPath("/Prototypes").SetSpecifier(Sdf.SpecifierClass)
    for i in range(3):
        fin = UsdGeom.Xform.Define(stage, f"/Luminaire/Fin{i}")
        fin.GetPrim().GetReferences().AddInternalReference(proto.GetPath())
        fin.GetPrim().SetInstanceable(True)
        fin.AddTranslateOp().Set(Gf.Vec3d(0, 0, i))
    add_disk(stage)
    scene = read(stage)
    assert stage.GetPrimAtPath("/Luminaire/Fin0").IsInstance()
    assert len(scene.triangles) == 3 * 2
    assert_allclose(sorted(set(scene.triangles[:, 0, 2])), [0, 1, 2])
    assert set(scene.parts) == {f"/Luminaire/Fin{i}/Blade" for i in range(3)}


def test_point_instancer_places_prototypes(tmp_path):
    stage = new_stage(tmp_path)
    instancer = UsdGeom.PointInstancer.Define(stage, "/Luminaire/Leds")
    add_mesh(stage, "/Luminaire/Leds/Protos/Quad")
    add_mesh(stage, "/Luminaire/Leds/Protos/Tri", points=QUAD[:3], counts=(3,),
             indices=(0, 1, 2))
    instancer.CreatePrototypesRel().SetTargets(
        [Sdf.Path("/Luminaire/Leds/Protos/Quad"), Sdf.Path("/Luminaire/Leds/Protos/Tri")])
    instancer.CreateProtoIndicesAttr([0, 0, 0, 1, 1])
    instancer.CreatePositionsAttr([Gf.Vec3f(0, 0, z) for z in range(5)])
    add_disk(stage)
    scene = read(stage)
    assert len(scene.triangles) == 3 * 2 + 2 * 1  # prototypes are not traced in place
    assert_allclose(sorted(set(scene.triangles[:, 0, 2])), [0, 1, 2, 3, 4])
    assert set(scene.parts) == {"/Luminaire/Leds/Protos/Quad", "/Luminaire/Leds/Protos/Tri"}

    instancer.InvisId(1, Usd.TimeCode.Default())
    scene = read(stage)
    assert len(scene.triangles) == 2 * 2 + 2 * 1


def test_point_instanced_lights_are_emitters(tmp_path):
    stage = new_stage(tmp_path)
    instancer = UsdGeom.PointInstancer.Define(stage, "/Luminaire/Leds")
    add_disk(stage, "/Luminaire/Leds/Protos/Led", flux=100.0)
    instancer.CreatePrototypesRel().SetTargets([Sdf.Path("/Luminaire/Leds/Protos/Led")])
    instancer.CreateProtoIndicesAttr([0, 0, 0])
    instancer.CreatePositionsAttr([Gf.Vec3f(x, 0, 0) for x in range(3)])
    scene = read(stage)
    assert len(scene.emitters) == 3 and len({e.path for e in scene.emitters}) == 3
    assert scene.total_flux == pytest.approx(300.0)
    assert_allclose(sorted(e.to_world[0, 3] for e in scene.emitters), [0, 1, 2])


def test_invisible_guide_proxy_and_inactive_prims_are_skipped(tmp_path):
    stage = new_stage(tmp_path)
    add_mesh(stage, "/Luminaire/Shown")
    add_mesh(stage, "/Luminaire/Hidden").MakeInvisible()
    hidden_group = UsdGeom.Xform.Define(stage, "/Luminaire/HiddenGroup")
    add_mesh(stage, "/Luminaire/HiddenGroup/Child")
    hidden_group.MakeInvisible()
    add_mesh(stage, "/Luminaire/Guide").CreatePurposeAttr(UsdGeom.Tokens.guide)
    add_mesh(stage, "/Luminaire/Proxy").CreatePurposeAttr(UsdGeom.Tokens.proxy)
    add_mesh(stage, "/Luminaire/Render").CreatePurposeAttr(UsdGeom.Tokens.render)
    add_mesh(stage, "/Luminaire/Inactive").GetPrim().SetActive(False)
    add_disk(stage)
    add_disk(stage, "/Luminaire/HiddenLed").MakeInvisible()
    add_disk(stage, "/Luminaire/InactiveLed").GetPrim().SetActive(False)
    scene = read(stage)
    assert set(scene.parts) == {"/Luminaire/Shown", "/Luminaire/Render"}
    assert [e.path for e in scene.emitters] == ["/Luminaire/Led"]


def test_holes_and_zero_area_triangles(tmp_path):
    stage = new_stage(tmp_path)
    mesh = add_mesh(stage, "/Luminaire/Part", points=QUAD + [(2, 0, 0)], counts=(3, 3, 3),
                    indices=(0, 1, 2, 0, 2, 3, 0, 1, 4))
    mesh.CreateHoleIndicesAttr([1])
    add_disk(stage)
    scene = read(stage)
    assert len(scene.triangles) == 1  # face 1 is a hole, face 2 is collinear
    assert any("/Luminaire/Part" in w and "zero-area" in w for w in scene.warnings)


def test_implicit_gprims_are_tessellated(tmp_path):
    stage = new_stage(tmp_path)
    UsdGeom.Cube.Define(stage, "/Luminaire/Cube").CreateSizeAttr(2.0)
    UsdGeom.Sphere.Define(stage, "/Luminaire/Sphere").CreateRadiusAttr(1.0)
    cylinder = UsdGeom.Cylinder.Define(stage, "/Luminaire/Cylinder")
    cylinder.CreateAxisAttr("X")
    UsdGeom.Plane.Define(stage, "/Luminaire/Plane").CreateAxisAttr("Y")
    UsdGeom.Capsule.Define(stage, "/Luminaire/Capsule")
    add_disk(stage)
    scene = read(stage)
    n = normals(scene.triangles)
    centres = scene.triangles.mean(axis=1)
    for part in ("/Luminaire/Cube", "/Luminaire/Sphere", "/Luminaire/Cylinder"):
        mask = scene.part_index == scene.parts.index(part)
        assert (np.einsum("ij,ij->i", n[mask], centres[mask]) > 0).all(), part  # outward
    cube = scene.part_index == scene.parts.index("/Luminaire/Cube")
    assert cube.sum() == 12
    sphere = scene.part_index == scene.parts.index("/Luminaire/Sphere")
    area = 0.5 * np.linalg.norm(np.cross(scene.triangles[sphere, 1] - scene.triangles[sphere, 0],
                                         scene.triangles[sphere, 2] - scene.triangles[sphere, 0]),
                                axis=1).sum()
    assert area == pytest.approx(4 * math.pi, rel=0.01)
    cyl = scene.triangles[scene.part_index == scene.parts.index("/Luminaire/Cylinder")]
    assert_allclose(np.abs(cyl[..., 0]).max(), 1.0)  # height 2 along x
    plane = scene.part_index == scene.parts.index("/Luminaire/Plane")
    assert_allclose(n[plane], [[0, 1, 0]] * 2, atol=1e-12)
    assert "/Luminaire/Capsule" not in scene.parts
    assert any("/Luminaire/Capsule" in w for w in scene.warnings)


# -- materials -------------------------------------------------------------------------

def test_preview_surface_mapping():
    assert preview_surface_values(diffuse_color=(0.5, 0.5, 0.5)) == {
        "lumitrace:scattering": "diffuse", "lumitrace:reflectance": pytest.approx(0.5)}
    assert luminance((1, 0, 0)) == pytest.approx(0.2126)
    mirror = preview_surface_values(diffuse_color=(0.9, 0.9, 0.9), metallic=1.0,
                                    roughness=0.01)
    assert mirror["lumitrace:scattering"] == "mirror"
    assert mirror["lumitrace:specularReflectance"] == pytest.approx(0.9)
    glossy = preview_surface_values(diffuse_color=(0.9, 0.9, 0.9), metallic=1.0,
                                    roughness=0.3)
    assert glossy["lumitrace:scattering"] == "glossy"
    assert glossy["lumitrace:roughness"] == pytest.approx(0.3)
    glass = preview_surface_values(opacity=0.1, ior=1.49)
    assert glass == {"lumitrace:scattering": "dielectric", "lumitrace:ior": pytest.approx(1.49),
                     "lumitrace:transmittance": pytest.approx(0.9)}
    specular = preview_surface_values(use_specular_workflow=1, specular_color=(0.8, 0.8, 0.8),
                                      roughness=0.0)
    assert specular["lumitrace:scattering"] == "mirror"
    assert specular["lumitrace:specularReflectance"] == pytest.approx(0.8)


def test_materials_from_preview_surface_and_schema(tmp_path):
    stage = new_stage(tmp_path)
    white = preview_material(stage, "/Luminaire/Looks/White",
                             diffuseColor=Gf.Vec3f(0.9, 0.8, 0.7))
    chrome = preview_material(stage, "/Luminaire/Looks/Chrome",
                              diffuseColor=Gf.Vec3f(0.95, 0.95, 0.95), metallic=1.0,
                              roughness=0.01)
    glass = preview_material(stage, "/Luminaire/Looks/Glass", opacity=0.0, ior=1.49)
    paint = preview_material(stage, "/Luminaire/Looks/Paint",
                             diffuseColor=Gf.Vec3f(0.5, 0.5, 0.5))
    paint.GetPrim().ApplyAPI("LumitraceMaterialAPI")
    paint.GetPrim().GetAttribute("lumitrace:reflectance").Set(0.93)
    names = ("White", "White2", "Chrome", "Glass", "Paint", "Override", "Bare")
    for name in names:
        add_mesh(stage, f"/Luminaire/{name}")
    for name, material in (("White", white), ("White2", white), ("Chrome", chrome),
                           ("Glass", glass), ("Paint", paint), ("Override", paint)):
        bind(stage.GetPrimAtPath(f"/Luminaire/{name}"), material)
    override = stage.GetPrimAtPath("/Luminaire/Override")
    override.ApplyAPI("LumitraceMaterialAPI")
    override.GetAttribute("lumitrace:scattering").Set("translucent")
    override.GetAttribute("lumitrace:transmittance").Set(0.15)
    add_disk(stage)
    scene = read(stage)

    white_m = material_of(scene, "/Luminaire/White")
    assert white_m.path == "/Luminaire/Looks/White"
    assert white_m.scattering == "diffuse"
    assert white_m.reflectance == pytest.approx(luminance((0.9, 0.8, 0.7)), rel=1e-6)
    assert material_of(scene, "/Luminaire/White2") is white_m  # deduplicated
    chrome_m = material_of(scene, "/Luminaire/Chrome")
    assert (chrome_m.scattering, chrome_m.specular_reflectance) == ("mirror", pytest.approx(0.95))
    glass_m = material_of(scene, "/Luminaire/Glass")
    assert (glass_m.scattering, glass_m.ior) == ("dielectric", pytest.approx(1.49))
    assert glass_m.transmittance == pytest.approx(1.0)
    paint_m = material_of(scene, "/Luminaire/Paint")
    assert paint_m.reflectance == pytest.approx(0.93)  # the schema overrides the preview
    over_m = material_of(scene, "/Luminaire/Override")
    assert over_m.path == "/Luminaire/Override"  # the API on the gprim wins ...
    assert over_m.scattering == "translucent" and over_m.transmittance == pytest.approx(0.15)
    assert over_m.reflectance == pytest.approx(0.8)  # ... with the schema fallbacks
    bare = material_of(scene, "/Luminaire/Bare")
    assert (bare.scattering, bare.reflectance) == ("diffuse", pytest.approx(0.8))
    assert sum("no material bound" in w for w in scene.warnings) == 1
    assert len(scene.materials) == 6


def test_material_api_fallbacks_on_material_prim(tmp_path):
    stage = new_stage(tmp_path)
    material = UsdShade.Material.Define(stage, "/Luminaire/Looks/Mirror")
    material.GetPrim().ApplyAPI("LumitraceMaterialAPI")
    material.GetPrim().GetAttribute("lumitrace:scattering").Set("mirror")
    bind(add_mesh(stage, "/Luminaire/Part").GetPrim(), material)
    add_disk(stage)
    m = read(stage).materials[0]
    assert (m.scattering, m.specular_reflectance, m.roughness, m.ior) == (
        "mirror", pytest.approx(1.0), pytest.approx(0.2), pytest.approx(1.5))


def test_geom_subset_materials(tmp_path):
    stage = new_stage(tmp_path)
    black = UsdShade.Material.Define(stage, "/Luminaire/Looks/Black")
    black.GetPrim().ApplyAPI("LumitraceMaterialAPI")
    black.GetPrim().GetAttribute("lumitrace:scattering").Set("absorber")
    white = preview_material(stage, "/Luminaire/Looks/White", diffuseColor=Gf.Vec3f(1, 1, 1))
    mesh = add_mesh(stage, "/Luminaire/Part", points=QUAD, counts=(3, 3),
                    indices=(0, 1, 2, 0, 2, 3))
    binding = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
    binding.Bind(white)
    subset = binding.CreateMaterialBindSubset("back", Vt.IntArray([1]))
    UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(black)
    add_disk(stage)
    scene = read(stage)
    kinds = [scene.materials[i].scattering for i in scene.material_index]
    assert kinds == ["diffuse", "absorber"]


# -- emitters --------------------------------------------------------------------------

def test_flux_from_intensity_exposure_and_color(tmp_path):
    stage = new_stage(tmp_path, meters_per_unit=0.001)
    sphere = UsdLux.SphereLight.Define(stage, "/Luminaire/Sphere")
    sphere.CreateRadiusAttr(5.0)
    sphere.CreateIntensityAttr(1000.0)
    sphere.CreateExposureAttr(2.0)
    sphere.CreateColorAttr(Gf.Vec3f(1.0, 0.5, 0.25))
    rect = UsdLux.RectLight.Define(stage, "/Luminaire/Rect")
    rect.CreateWidthAttr(20.0)
    rect.CreateHeightAttr(10.0)
    rect.CreateIntensityAttr(500.0)
    rect.AddScaleOp().Set(Gf.Vec3f(2.0, 3.0, 7.0))  # z scale does not change the area
    disk = UsdLux.DiskLight.Define(stage, "/Luminaire/Disk")
    disk.CreateRadiusAttr(30.0)
    disk.CreateIntensityAttr(100.0)
    disk.CreateNormalizeAttr(True)
    cylinder = UsdLux.CylinderLight.Define(stage, "/Luminaire/Cylinder")
    cylinder.CreateRadiusAttr(2.0)
    cylinder.CreateLengthAttr(100.0)
    cylinder.CreateIntensityAttr(50.0)
    cylinder.CreateExposureAttr(-1.0)
    scene = read(stage)
    flux = {e.path.rsplit("/", 1)[1]: e.flux for e in scene.emitters}
    y = 0.2126 + 0.7152 * 0.5 + 0.0722 * 0.25
    assert flux["Sphere"] == pytest.approx(math.pi * 1000 * 4 * y * 4 * math.pi * 0.005 ** 2)
    assert flux["Rect"] == pytest.approx(math.pi * 500 * (0.020 * 2) * (0.010 * 3))
    assert flux["Disk"] == pytest.approx(math.pi * 100)
    assert flux["Cylinder"] == pytest.approx(math.pi * 25 * 2 * math.pi * 0.002 * 0.1)
    kinds = {e.path.rsplit("/", 1)[1]: e.kind for e in scene.emitters}
    assert kinds == {"Sphere": "sphere", "Rect": "rect", "Disk": "disk", "Cylinder": "cylinder"}
    assert light_flux("disk", 100.0, 1.0, area=2.0) == pytest.approx(math.pi * 400)


def test_sphere_area_under_non_uniform_scale(tmp_path):
    stage = new_stage(tmp_path)
    sphere = UsdLux.SphereLight.Define(stage, "/Luminaire/Sphere")
    sphere.CreateRadiusAttr(1.0)
    sphere.CreateIntensityAttr(1.0)
    sphere.AddScaleOp().Set(Gf.Vec3f(1.0, 1.0, 2.0))
    scene = read(stage)
    # prolate spheroid a = 1, c = 2: area = 2 pi a^2 (1 + c/(a e) asin e), e^2 = 1 - a^2/c^2
    e = math.sqrt(1 - 1 / 4)
    area = 2 * math.pi * (1 + 2 / e * math.asin(e))
    assert scene.emitters[0].flux == pytest.approx(math.pi * area, rel=1e-6)


def test_shaping_cone(tmp_path):
    stage = new_stage(tmp_path)
    shaped = add_disk(stage, "/Luminaire/Shaped", flux=None, radius=0.1)
    shaped.CreateIntensityAttr(1000.0)
    shaping = UsdLux.ShapingAPI.Apply(shaped.GetPrim())
    shaping.CreateShapingConeAngleAttr(30.0)
    shaping.CreateShapingConeSoftnessAttr(0.0)
    lumens = add_disk(stage, "/Luminaire/Lumens", flux=800.0)
    UsdLux.ShapingAPI.Apply(lumens.GetPrim()).CreateShapingConeAngleAttr(20.0)
    scene = read(stage)
    by_path = {e.path: e for e in scene.emitters}
    full = math.pi * 1000 * math.pi * 0.01
    assert by_path["/Luminaire/Shaped"].flux == pytest.approx(full * 0.25)
    assert by_path["/Luminaire/Shaped"].cone_angle == pytest.approx(30.0)
    assert by_path["/Luminaire/Lumens"].flux == pytest.approx(800.0)  # as authored
    assert by_path["/Luminaire/Lumens"].cone_angle == pytest.approx(20.0)


def test_shaping_fraction():
    assert shaping_fraction("disk", 30.0) == pytest.approx(0.25)
    assert shaping_fraction("disk", 90.0) == pytest.approx(1.0)
    assert shaping_fraction("sphere", 180.0) == pytest.approx(1.0)
    assert shaping_fraction("sphere", 90.0) == pytest.approx(0.5)
    # cos^focus on a Lambertian disk: 2 / (focus + 2)
    assert shaping_fraction("disk", 90.0, 0.0, 3.0) == pytest.approx(0.4, rel=1e-6)
    soft = shaping_fraction("disk", 40.0, 0.5)
    assert math.sin(math.radians(20)) ** 2 < soft < math.sin(math.radians(40)) ** 2


def test_unshaped_emitters(tmp_path):
    stage = new_stage(tmp_path)
    add_disk(stage)
    sphere = UsdLux.SphereLight.Define(stage, "/Luminaire/Bulb")
    sphere.GetPrim().ApplyAPI("LumitraceEmitterAPI")
    sphere.GetPrim().GetAttribute("lumitrace:luminousFlux").Set(500.0)
    sphere.CreateTreatAsPointAttr(True)
    scene = read(stage)
    by_path = {e.path: e for e in scene.emitters}
    assert by_path["/Luminaire/Led"].cone_angle == 90.0
    assert by_path["/Luminaire/Bulb"].cone_angle == 180.0
    assert by_path["/Luminaire/Bulb"].treat_as_point
    assert scene.total_flux == pytest.approx(1500.0)


def test_emitter_to_world_is_column_convention(tmp_path):
    stage = new_stage(tmp_path, meters_per_unit=0.01)
    light = add_disk(stage)
    light.AddTranslateOp().Set(Gf.Vec3d(1, 2, 3))
    light.AddRotateZOp().Set(90.0)
    emitter = read(stage).emitters[0]
    m = emitter.to_world
    assert m.shape == (4, 4) and m.dtype == np.float64
    assert_allclose(m[:3, 3], [0.01, 0.02, 0.03], atol=1e-12)
    assert_allclose(m[:3, :3] @ [1, 0, 0], [0, 0.01, 0], atol=1e-12)
    assert_allclose(m[3], [0, 0, 0, 1])


def test_unsupported_lights_are_skipped_with_a_warning(tmp_path):
    stage = new_stage(tmp_path)
    add_disk(stage)
    UsdLux.DistantLight.Define(stage, "/Luminaire/Sun")
    scene = read(stage)
    assert len(scene.emitters) == 1
    assert any("/Luminaire/Sun" in w for w in scene.warnings)


# -- errors ----------------------------------------------------------------------------

def test_missing_unreadable_and_empty_stages(tmp_path):
    with pytest.raises(StageError, match="not found") as info:
        read_stage(tmp_path / "missing.usda")
    assert "missing.usda" in str(info.value)
    text = tmp_path / "notes.txt"
    text.write_text("not a stage")
    with pytest.raises(StageError, match="notes.txt"):
        read_stage(text)
    broken = tmp_path / "broken.usda"
    broken.write_text('#usda 1.0\ndef Xform "A" { float x = [ }\n')
    with pytest.raises(StageError, match="broken.usda"):
        read_stage(broken)
    empty = Usd.Stage.CreateNew(str(tmp_path / "empty.usda"))
    empty.Save()
    with pytest.raises(StageError, match="empty"):
        read_stage(tmp_path / "empty.usda")
    with pytest.raises(StageError, match="folder"):
        read_stage(tmp_path)


def test_no_emitter_and_bad_luminaire(tmp_path):
    stage = new_stage(tmp_path)
    add_mesh(stage, "/Luminaire/Part")
    expect_error(stage, "/Luminaire", "no emitter")
    add_disk(stage)
    expect_error(stage, "/Nope", "no such active prim", luminaire="/Nope")
    stage.GetRootLayer().defaultPrim = "Missing"
    expect_error(stage, "defaultPrim", "Missing")


def test_light_without_flux(tmp_path):
    stage = new_stage(tmp_path)
    add_disk(stage, flux=None)
    expect_error(stage, "/Luminaire/Led: light has no luminous flux: author "
                        "lumitrace:luminousFlux (lm) or inputs:intensity")


@pytest.mark.parametrize("value", [-5.0, 0.0, float("nan"), float("inf")])
def test_bad_luminous_flux(tmp_path, value):
    stage = new_stage(tmp_path)
    add_disk(stage, flux=value)
    expect_error(stage, "/Luminaire/Led.lumitrace:luminousFlux")


def test_bad_light_values(tmp_path):
    stage = new_stage(tmp_path)
    light = add_disk(stage, radius=0.0)
    expect_error(stage, "/Luminaire/Led.inputs:radius")
    light.GetRadiusAttr().Set(0.05)
    light.GetPrim().GetAttribute("lumitrace:luminousFlux").Clear()
    light.CreateIntensityAttr(float("nan"))
    expect_error(stage, "/Luminaire/Led.inputs:intensity")
    light.GetIntensityAttr().Set(0.0)
    expect_error(stage, "/Luminaire/Led.inputs:intensity", "no flux")


def test_nan_points(tmp_path):
    stage = new_stage(tmp_path)
    nan = float("nan")
    add_mesh(stage, "/Luminaire/Reflector",
             points=[(nan, 0, 0), (1, nan, 0), (1, 1, float("inf")), (0, 1, 0)])
    add_disk(stage)
    expect_error(stage, "/Luminaire/Reflector.points: 3 points are NaN or infinite")


def test_nan_transform(tmp_path):
    stage = new_stage(tmp_path)
    group = UsdGeom.Xform.Define(stage, "/Luminaire/Group")
    group.AddTranslateOp().Set(Gf.Vec3d(float("nan"), 0, 0))
    add_mesh(stage, "/Luminaire/Group/Part")
    add_disk(stage)
    expect_error(stage, "/Luminaire/Group.xformOp:translate", "NaN")


def test_bad_topology(tmp_path):
    stage = new_stage(tmp_path)
    add_mesh(stage, "/Luminaire/Part", indices=(0, 1, 2, 9))
    add_disk(stage)
    expect_error(stage, "/Luminaire/Part.faceVertexIndices")


def test_nan_instancer_positions(tmp_path):
    stage = new_stage(tmp_path)
    instancer = UsdGeom.PointInstancer.Define(stage, "/Luminaire/Leds")
    add_mesh(stage, "/Luminaire/Leds/Quad")
    instancer.CreatePrototypesRel().SetTargets([Sdf.Path("/Luminaire/Leds/Quad")])
    instancer.CreateProtoIndicesAttr([0, 0])
    instancer.CreatePositionsAttr([Gf.Vec3f(0, 0, 0), Gf.Vec3f(float("nan"), 0, 0)])
    add_disk(stage)
    expect_error(stage, "/Luminaire/Leds.positions", "NaN")


@pytest.mark.parametrize("prop, value, fragment", [
    ("lumitrace:scattering", "shiny", "unknown scattering"),
    ("lumitrace:reflectance", 1.5, "[0, 1]"),
    ("lumitrace:reflectance", float("nan"), "[0, 1]"),
    ("lumitrace:specularReflectance", -0.1, "[0, 1]"),
    ("lumitrace:transmittance", 2.0, "[0, 1]"),
    ("lumitrace:ior", 0.0, "> 0"),
    ("lumitrace:ior", float("nan"), "finite"),
    ("lumitrace:roughness", 1.2, "[0, 1]"),
])
@pytest.mark.parametrize("on", ["material", "gprim"])
def test_bad_material_values(tmp_path, prop, value, fragment, on):
    stage = new_stage(tmp_path)
    material = UsdShade.Material.Define(stage, "/Luminaire/Looks/Bad")
    mesh = add_mesh(stage, "/Luminaire/Part")
    bind(mesh.GetPrim(), material)
    target = material.GetPrim() if on == "material" else mesh.GetPrim()
    target.ApplyAPI("LumitraceMaterialAPI")
    target.GetAttribute(prop).Set(value)
    add_disk(stage)
    expect_error(stage, f"{target.GetPath()}.{prop}", fragment)


def test_translucent_sum_above_one(tmp_path):
    stage = new_stage(tmp_path)
    mesh = add_mesh(stage, "/Luminaire/Diffuser").GetPrim()
    mesh.ApplyAPI("LumitraceMaterialAPI")
    mesh.GetAttribute("lumitrace:scattering").Set("translucent")
    mesh.GetAttribute("lumitrace:reflectance").Set(0.6)
    mesh.GetAttribute("lumitrace:transmittance").Set(0.5)
    add_disk(stage)
    expect_error(stage, "/Luminaire/Diffuser.lumitrace:transmittance", "exceeds 1")


def test_authored_attribute_without_the_api_counts(tmp_path):
    """Authored lumitrace attributes count even where the API is not applied (e.g. a DCC
    that wrote the attributes but not the apiSchemas metadata), and are validated."""
    stage = new_stage(tmp_path)
    mesh = add_mesh(stage, "/Luminaire/Part").GetPrim()
    mesh.CreateAttribute("lumitrace:scattering", Sdf.ValueTypeNames.Token,
                         variability=Sdf.VariabilityUniform).Set("absorber")
    add_disk(stage)
    assert read(stage).materials[0].scattering == "absorber"
    mesh.GetAttribute("lumitrace:scattering").Set("black")
    expect_error(stage, "/Luminaire/Part.lumitrace:scattering", "black")


def test_unauthored_meters_per_unit_is_centimetres_with_a_warning(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "plain.usda"))
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/Luminaire").GetPrim())
    add_mesh(stage, "/Luminaire/Part")
    add_disk(stage)
    scene = read(stage)
    assert scene.meters_per_unit == pytest.approx(0.01)
    assert_allclose(scene.triangles.reshape(-1, 3).max(axis=0), [0.01, 0.01, 0])
    assert any("metersPerUnit is not authored" in w for w in scene.warnings)


def test_authored_gprim_values_combine_with_each_subset_material(tmp_path):
    stage = new_stage(tmp_path)
    red = preview_material(stage, "/Luminaire/Looks/Red", diffuseColor=Gf.Vec3f(1, 0, 0))
    green = preview_material(stage, "/Luminaire/Looks/Green", diffuseColor=Gf.Vec3f(0, 1, 0))
    mesh = add_mesh(stage, "/Luminaire/Part", points=QUAD, counts=(3, 3),
                    indices=(0, 1, 2, 0, 2, 3))
    binding = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
    binding.Bind(red)
    subset = binding.CreateMaterialBindSubset("second", Vt.IntArray([1]))
    UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(green)
    mesh.GetPrim().CreateAttribute("lumitrace:roughness", Sdf.ValueTypeNames.Float).Set(0.4)
    add_disk(stage)
    scene = read(stage)
    first, second = (scene.materials[i] for i in scene.material_index)
    assert first.reflectance == pytest.approx(0.2126, rel=1e-6)
    assert second.reflectance == pytest.approx(0.7152, rel=1e-6)
    assert first.roughness == pytest.approx(0.4) and second.roughness == pytest.approx(0.4)


LATE_REGISTRATION = """
import sys, warnings
from pxr import Usd
Usd.Stage.CreateInMemory().DefinePrim("/A", "Mesh")  # loads the schema registry
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    import lumitrace
from lumitrace.schema import is_registered
from lumitrace.stage import read_stage
assert not is_registered() and any("registered after" in str(w.message) for w in caught)
material = read_stage(sys.argv[1]).materials[0]
assert (material.scattering, material.specular_reflectance) == ("mirror", 1.0), material
print("ok")
"""


def test_applied_api_counts_even_when_the_schema_registered_too_late(tmp_path):
    """Schema fallbacks apply where apiSchemas lists the API, even if USD could not load
    the schema in this process."""
    import subprocess
    import sys

    stage = new_stage(tmp_path)
    mesh = add_mesh(stage, "/Luminaire/Part").GetPrim()
    mesh.ApplyAPI("LumitraceMaterialAPI")
    mesh.GetAttribute("lumitrace:scattering").Set("mirror")
    add_disk(stage)
    stage.Save()
    # a process of its own: not a child of one that imported lumitrace, whose plugin path
    # (PXR_PLUGINPATH_NAME) it would inherit
    env = {k: v for k, v in os.environ.items() if k != PLUGIN_PATH_VARIABLE}
    result = subprocess.run([sys.executable, "-c", LATE_REGISTRATION,
                             stage.GetRootLayer().realPath],
                            capture_output=True, text=True, timeout=120, env=env)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "ok"
    assert "registered after" not in result.stderr  # said once, not again by the reader
