"""Reading a stage at one time code, never tracing lumitrace's own photometric stand-in,
and luminous flux limits named at the light's property."""
from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)
from lumitrace.errors import StageError
from lumitrace.stage import read_stage, scene_from_stage
from lumitrace.stage import representation, validate
from pxr import Gf, Sdf, Usd, UsdGeom

from helpers.stages import QUAD, add_disk, add_mesh, expect_error, new_stage, read

RADIUS = 0.05
DISK_AREA = math.pi * RADIUS ** 2


def disk_flux(luminance, area=DISK_AREA):
    """Flux of a one-sided Lambertian disk, normalize off: pi * L * A."""
    return math.pi * luminance * area


def animation_warnings(scene):
    return [w for w in scene.warnings if "animated" in w]


def intensity_disk(stage, samples, path="/Luminaire/Led"):
    light = add_disk(stage, path, flux=None, radius=RADIUS)
    attr = light.CreateIntensityAttr()
    for time, value in samples.items():
        attr.Set(value, time)
    return light


# -- time samples ----------------------------------------------------------------------

def test_time_sampled_intensity_is_read_at_the_start_time_code(tmp_path):
    stage = new_stage(tmp_path)
    intensity_disk(stage, {1.0: 100.0, 2.0: 200.0})
    stage.SetStartTimeCode(2.0)
    scene = read(stage)
    assert scene.time_code == 2.0
    assert scene.emitters[0].flux == pytest.approx(disk_flux(200.0), rel=1e-6)
    assert scene.emitters[0].flux == pytest.approx(0.0025 * math.pi ** 2 * 200.0, rel=1e-6)
    (warning,) = animation_warnings(scene)
    assert warning == ("/Luminaire: 1 attribute is animated (e.g. /Luminaire/Led."
                       "inputs:intensity): the luminaire is read at time code 2 (the "
                       "stage's startTimeCode)")


def test_without_a_start_time_code_the_earliest_sample_is_used(tmp_path):
    stage = new_stage(tmp_path)
    intensity_disk(stage, {3.0: 300.0, 1.5: 100.0, 2.0: 200.0})
    scene = read(stage)
    assert scene.time_code == 1.5
    assert scene.emitters[0].flux == pytest.approx(disk_flux(100.0), rel=1e-6)
    (warning,) = animation_warnings(scene)
    assert "time code 1.5 (its earliest time sample)" in warning


def test_a_given_time_is_used_as_it_is_without_a_warning(tmp_path):
    stage = new_stage(tmp_path)
    intensity_disk(stage, {1.0: 100.0, 2.0: 200.0})
    stage.SetStartTimeCode(1.0)
    scene = read(stage, time=1.5)  # linear interpolation between the samples
    assert scene.time_code == 1.5
    assert scene.emitters[0].flux == pytest.approx(disk_flux(150.0), rel=1e-6)
    assert not animation_warnings(scene)
    scene = read(stage, time=Usd.TimeCode(2.0))
    assert scene.emitters[0].flux == pytest.approx(disk_flux(200.0), rel=1e-6)
    # the default time, asked for: the fallback intensity 1, as before
    scene = read(stage, time=Usd.TimeCode.Default())
    assert scene.time_code is None
    assert scene.emitters[0].flux == pytest.approx(disk_flux(1.0), rel=1e-6)


def test_a_static_stage_is_read_at_the_default_time(tmp_path):
    stage = new_stage(tmp_path)
    add_mesh(stage, "/Luminaire/Part")
    light = add_disk(stage, flux=None)
    light.CreateIntensityAttr(1000.0)
    stage.SetStartTimeCode(7.0)  # authored, but nothing is animated
    scene = read(stage)
    assert scene.time_code is None
    assert not animation_warnings(scene)
    assert scene.emitters[0].flux == pytest.approx(disk_flux(1000.0), rel=1e-6)
    default = read(stage, time=Usd.TimeCode.Default())
    assert np.array_equal(scene.triangles, default.triangles)
    assert scene.content_hash() == default.content_hash()


def test_time_sampled_points_are_read_at_the_chosen_time(tmp_path):
    stage = new_stage(tmp_path)
    mesh = UsdGeom.Mesh.Define(stage, "/Luminaire/Part")
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    points = mesh.CreatePointsAttr()
    points.Set([Gf.Vec3f(*p) for p in QUAD], 3.0)
    points.Set([Gf.Vec3f(*(2.0 * c for c in p)) for p in QUAD], 5.0)
    add_disk(stage)
    scene = read(stage)  # earliest sample: 3
    assert scene.time_code == 3.0
    assert_allclose(scene.triangles, [[(0, 0, 0), (1, 0, 0), (1, 1, 0)],
                                      [(0, 0, 0), (1, 1, 0), (0, 1, 0)]])
    stage.SetStartTimeCode(5.0)
    scene = read(stage)
    assert scene.time_code == 5.0
    assert_allclose(scene.triangles, [[(0, 0, 0), (2, 0, 0), (2, 2, 0)],
                                      [(0, 0, 0), (2, 2, 0), (0, 2, 0)]])
    (warning,) = animation_warnings(scene)
    assert "/Luminaire/Part.points" in warning and "time code 5" in warning


def test_time_sampled_translate_moves_triangles_and_lights(tmp_path):
    stage = new_stage(tmp_path)
    part = UsdGeom.Xform.Define(stage, "/Luminaire/Part")
    op = part.AddTranslateOp()
    op.Set(Gf.Vec3d(0.0, 0.0, 0.0), 0.0)
    op.Set(Gf.Vec3d(0.0, 0.0, 4.0), 10.0)
    add_mesh(stage, "/Luminaire/Part/Reflector")
    light = add_disk(stage, "/Luminaire/Part/Led")
    light.AddTranslateOp().Set(Gf.Vec3d(1.0, 0.0, 0.0))
    stage.SetStartTimeCode(10.0)
    scene = read(stage)
    assert_allclose(scene.triangles[0], [(0, 0, 4), (1, 0, 4), (1, 1, 4)])
    assert_allclose(scene.emitters[0].to_world[:3, 3], [1, 0, 4])
    (warning,) = animation_warnings(scene)
    assert "/Luminaire/Part.xformOp:translate" in warning
    scene = read(stage, time=5.0)  # every read at the one time: half way
    assert_allclose(scene.triangles[0], [(0, 0, 2), (1, 0, 2), (1, 1, 2)])
    assert_allclose(scene.emitters[0].to_world[:3, 3], [1, 0, 2])


def test_animated_materials_visibility_and_instancers_use_the_same_time(tmp_path):
    stage = new_stage(tmp_path)
    paint = add_mesh(stage, "/Luminaire/Paint").GetPrim()
    reflectance = paint.CreateAttribute("lumitrace:reflectance", Sdf.ValueTypeNames.Float)
    reflectance.Set(0.2, 1.0)
    reflectance.Set(0.6, 2.0)
    hidden = add_mesh(stage, "/Luminaire/Hidden", scale=3.0)
    visibility = hidden.CreateVisibilityAttr()
    visibility.Set(UsdGeom.Tokens.inherited, 1.0)
    visibility.Set(UsdGeom.Tokens.invisible, 2.0)
    instancer = UsdGeom.PointInstancer.Define(stage, "/Luminaire/Leds")
    add_disk(stage, "/Luminaire/Leds/Proto")
    instancer.CreatePrototypesRel().AddTarget("/Luminaire/Leds/Proto")
    instancer.CreateProtoIndicesAttr([0, 0])
    positions = instancer.CreatePositionsAttr()
    positions.Set([Gf.Vec3f(0, 0, 1), Gf.Vec3f(0, 0, 2)], 1.0)
    positions.Set([Gf.Vec3f(0, 0, 5), Gf.Vec3f(0, 0, 6)], 2.0)
    stage.SetStartTimeCode(2.0)
    scene = read(stage)
    assert scene.parts == ("/Luminaire/Paint",)  # invisible at time 2
    assert scene.materials[0].reflectance == pytest.approx(0.6)
    assert sorted(e.to_world[2, 3] for e in scene.emitters) == pytest.approx([5.0, 6.0])
    (warning,) = animation_warnings(scene)
    assert warning.startswith("/Luminaire: 3 attributes are animated")
    scene = read(stage, time=1.0)
    assert scene.parts == ("/Luminaire/Paint", "/Luminaire/Hidden")
    assert scene.materials[0].reflectance == pytest.approx(0.2)
    assert sorted(e.to_world[2, 3] for e in scene.emitters) == pytest.approx([1.0, 2.0])


# -- lumitrace's own photometric representation ----------------------------------------

def traced_stage_with_result_layer(tmp_path, select=None):
    """A luminaire with one LED and a reflector, and the result layer lumitrace writes for
    it (variant set lumitraceRepresentation, stand-in light of 5000 lm)."""
    from lumitrace.publish.result_layer import write_result_layer

    stage = new_stage(tmp_path)
    add_mesh(stage, "/Luminaire/Reflector")
    led = add_disk(stage, "/Luminaire/LED", flux=1234.0)
    led.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 0.5))
    stage.Save()
    path = tmp_path / "luminaire.usda"
    write_result_layer(path, "/Luminaire", {}, light={
        "ies": "luminaire.ies", "flux": 5000.0, "radius": 0.2, "position": (0.0, 0.0, 0.0),
        "emitters": ["/Luminaire/LED"]})
    if select:
        layer = Sdf.Layer.FindOrOpen(str(path))
        Sdf.CreatePrimInLayer(layer, "/Luminaire").variantSelections[
            representation.REPRESENTATION] = select
        layer.Save()
    return path


def assert_modelled_luminaire(scene):
    assert [e.path for e in scene.emitters] == ["/Luminaire/LED"]
    assert scene.emitters[0].flux == pytest.approx(1234.0)
    assert scene.total_flux == pytest.approx(1234.0)
    assert_allclose(scene.emitters[0].to_world[:3, 3], [0, 0, 0.5])
    assert scene.parts == ("/Luminaire/Reflector",)
    assert any(w.startswith("/Luminaire: variant set lumitraceRepresentation selects "
                            "'photometric'") for w in scene.warnings), scene.warnings


def test_the_names_match_the_result_layer():
    from lumitrace.publish import result_layer

    assert representation.REPRESENTATION == result_layer.REPRESENTATION
    assert representation.PHOTOMETRIC_LIGHT == result_layer.PHOTOMETRIC_LIGHT


def test_the_geometry_variant_is_read_as_it_is(tmp_path):
    path = traced_stage_with_result_layer(tmp_path)
    scene = read_stage(path)
    assert [e.path for e in scene.emitters] == ["/Luminaire/LED"]
    assert scene.emitters[0].flux == pytest.approx(1234.0)
    assert not any("lumitraceRepresentation" in w or "stand-in" in w for w in scene.warnings)


def test_a_photometric_selection_in_the_stage_is_read_as_geometry(tmp_path):
    path = traced_stage_with_result_layer(tmp_path, select="photometric")
    files = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    check = Usd.Stage.Open(str(path))  # what the stage composes to: the stand-in
    assert check.GetPrimAtPath("/Luminaire/lumitracePhotometricLight")
    assert not check.GetPrimAtPath("/Luminaire/LED").IsActive()
    scene = read_stage(path)
    assert_modelled_luminaire(scene)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == files  # nothing written


def test_a_photometric_selection_in_the_session_layer_is_restored(tmp_path):
    path = traced_stage_with_result_layer(tmp_path)
    stage = Usd.Stage.Open(str(path))
    session = stage.GetSessionLayer()
    with Usd.EditContext(stage, session):
        stage.GetPrimAtPath("/Luminaire").GetVariantSets().GetVariantSet(
            representation.REPRESENTATION).SetVariantSelection("photometric")
    before = session.ExportToString()
    scene = scene_from_stage(stage)
    assert_modelled_luminaire(scene)
    assert session.ExportToString() == before
    prim = stage.GetPrimAtPath("/Luminaire")
    assert prim.GetVariantSets().GetVariantSelection(representation.REPRESENTATION) == \
        "photometric"
    assert stage.GetPrimAtPath("/Luminaire/lumitracePhotometricLight")
    assert not stage.GetPrimAtPath("/Luminaire/LED").IsActive()


def test_the_session_layer_is_restored_after_an_error(tmp_path):
    path = traced_stage_with_result_layer(tmp_path, select="photometric")
    stage = Usd.Stage.Open(str(path))
    stage.GetPrimAtPath("/Luminaire/LED").GetAttribute("lumitrace:luminousFlux").Set(-1.0)
    with pytest.raises(StageError, match="/Luminaire/LED.lumitrace:luminousFlux"):
        scene_from_stage(stage)
    assert not stage.GetSessionLayer().rootPrims
    assert stage.GetPrimAtPath("/Luminaire").GetVariantSets().GetVariantSelection(
        representation.REPRESENTATION) == "photometric"


def test_an_empty_session_layer_is_left_empty(tmp_path):
    path = traced_stage_with_result_layer(tmp_path, select="photometric")
    stage = Usd.Stage.Open(str(path))
    before = stage.GetSessionLayer().ExportToString()
    assert_modelled_luminaire(scene_from_stage(stage))
    assert stage.GetSessionLayer().ExportToString() == before
    assert not stage.GetSessionLayer().rootPrims


@pytest.mark.parametrize("session", ["none", "locked"])
def test_without_an_editable_session_layer_a_second_stage_is_read(tmp_path, session):
    path = traced_stage_with_result_layer(tmp_path, select="photometric")
    root = Sdf.Layer.FindOrOpen(str(path))
    if session == "none":
        stage = Usd.Stage.Open(root, sessionLayer=None)
        assert stage.GetSessionLayer() is None
    else:
        layer = Sdf.Layer.CreateAnonymous("locked.usda")
        layer.SetPermissionToEdit(False)
        stage = Usd.Stage.Open(root, layer)
    assert_modelled_luminaire(scene_from_stage(stage))
    assert stage.GetPrimAtPath("/Luminaire/lumitracePhotometricLight")


def test_the_stand_in_light_is_never_traced(tmp_path):
    stage = new_stage(tmp_path)
    add_mesh(stage, "/Luminaire/Reflector")
    add_disk(stage, "/Luminaire/LED", flux=800.0)
    add_disk(stage, "/Luminaire/lumitracePhotometricLight", flux=5000.0)
    scene = read(stage)
    assert [e.path for e in scene.emitters] == ["/Luminaire/LED"]
    assert scene.total_flux == pytest.approx(800.0)
    assert ("/Luminaire/lumitracePhotometricLight: the stand-in light of lumitrace's "
            "photometric representation (its own result) is not traced: skipped"
            ) in scene.warnings
    # the name counts only directly under the luminaire
    add_disk(stage, "/Luminaire/Optic/lumitracePhotometricLight", flux=100.0)
    scene = read(stage)
    assert sorted(e.path for e in scene.emitters) == [
        "/Luminaire/LED", "/Luminaire/Optic/lumitracePhotometricLight"]
    assert scene.total_flux == pytest.approx(900.0)


def test_a_stand_in_light_alone_is_no_emitter(tmp_path):
    stage = new_stage(tmp_path)
    add_mesh(stage, "/Luminaire/Reflector")
    add_disk(stage, "/Luminaire/lumitracePhotometricLight", flux=5000.0)
    expect_error(stage, "/Luminaire: no emitter")


# -- flux limits -----------------------------------------------------------------------

def test_an_authored_flux_above_the_limit_names_the_property(tmp_path):
    stage = new_stage(tmp_path)
    add_disk(stage, flux=1e30)
    message = expect_error(stage, "/Luminaire/Led.lumitrace:luminousFlux: luminous flux of "
                                  "1e+30 lm is above the 1e+24 lm lumitrace can trace")
    assert "\n" not in message
    assert validate.MAX_LUMINOUS_FLUX == 1e24


def test_a_flux_at_the_limit_is_traced(tmp_path):
    stage = new_stage(tmp_path)
    add_disk(stage, flux=1e24)
    scene = read(stage)
    # lumitrace:luminousFlux is a float: 1e24 as float32 holds it, a little above, passes
    assert scene.total_flux == float(np.float32(1e24)) > 1e24


def test_an_intensity_flux_above_the_limit_names_intensity(tmp_path):
    stage = new_stage(tmp_path)
    light = add_disk(stage, flux=None)
    light.CreateIntensityAttr(1e30)  # pi * 1e30 * pi * 0.05**2 = 2.5e28 lm
    message = expect_error(stage, "/Luminaire/Led.inputs:intensity: luminous flux from "
                                  "intensity 1e+30", "above the 1e+24 lm")
    assert f"{disk_flux(1e30):g}".split("e")[1] in message


@pytest.mark.parametrize("exposure", [80.0, 1e4])
def test_an_exposure_that_takes_the_flux_above_the_limit_names_exposure(tmp_path, exposure):
    stage = new_stage(tmp_path)
    light = add_disk(stage, flux=None)
    light.CreateIntensityAttr(1000.0)
    light.CreateExposureAttr(exposure)  # 2**80 = 1.2e24: 3e25 lm; 2**1e4: infinite
    expect_error(stage, "/Luminaire/Led.inputs:exposure: luminous flux from intensity 1000, "
                        f"exposure {exposure:g}", "above the 1e+24 lm")
    light.GetExposureAttr().Set(60.0)  # 2.8e19 lm: traced
    scene = read(stage)
    assert scene.emitters[0].flux == pytest.approx(disk_flux(1000.0 * 2.0 ** 60), rel=1e-6)


def test_a_time_sampled_flux_is_checked_at_the_time_read(tmp_path):
    stage = new_stage(tmp_path)
    intensity_disk(stage, {1.0: 100.0, 2.0: 1e30})
    assert read(stage).emitters[0].flux == pytest.approx(disk_flux(100.0), rel=1e-6)
    stage.SetStartTimeCode(2.0)
    expect_error(stage, "/Luminaire/Led.inputs:intensity", "above the 1e+24 lm")


def test_a_total_flux_above_the_limit_names_the_luminaire(tmp_path):
    stage = new_stage(tmp_path)
    add_disk(stage, "/Luminaire/A", flux=6e23)
    add_disk(stage, "/Luminaire/B", flux=6e23)
    expect_error(stage, "/Luminaire: total luminous flux of its 2 emitters of 1.2e+24 lm is "
                        "above the 1e+24 lm lumitrace can trace")
    stage.GetPrimAtPath("/Luminaire/B").GetAttribute("lumitrace:luminousFlux").Set(4e23)
    assert read(stage).total_flux == pytest.approx(1e24, rel=1e-6)
