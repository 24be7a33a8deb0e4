"""Reading colour from a stage: lights' spectra (sampled, named, UsdLux colour temperature
and colour), surfaces' spectral albedos (authored or recovered from a preview colour), a
dielectric's dispersion, and one clear error for each bad value."""
import numpy as np
import pytest
from pxr import Gf, Sdf, UsdLux, UsdShade

from lumitrace.scene import spectra
from helpers.stages import add_disk, add_mesh, expect_error, new_stage, read


def _light(tmp_path, **attrs):
    stage = new_stage(tmp_path)
    light = add_disk(stage)
    for name, (kind, value) in attrs.items():
        light.GetPrim().CreateAttribute(name, kind).Set(value)
    return stage, light


def _cct(spd):
    from lumitrace.photometry.colour import cct_duv, uv_prime

    return float(cct_duv(uv_prime(spectra.tristimulus(spd)))[0])


def test_a_light_without_colour_has_none(tmp_path):
    stage, _ = _light(tmp_path)
    scene = read(stage)
    assert scene.emitters[0].spectrum == () and scene.colour == "none"


@pytest.mark.parametrize("cct", [2700.0, 4000.0, 6500.0])
def test_named_and_usdlux_colour_temperatures(tmp_path, cct):
    stage, light = _light(tmp_path, **{"lumitrace:illuminant": (Sdf.ValueTypeNames.String,
                                                                 f"blackbody {cct:g}")})
    spd = np.asarray(read(stage).emitters[0].spectrum)
    assert _cct(spd) == pytest.approx(cct, abs=2.0)
    # UsdLux's own colour temperature is a Planckian radiator too
    light.GetPrim().GetAttribute("lumitrace:illuminant").Clear()
    light.CreateEnableColorTemperatureAttr(True)
    light.CreateColorTemperatureAttr(cct)
    assert np.allclose(read(stage).emitters[0].spectrum, spd, rtol=1e-12)
    # and CIE daylight of the same correlated colour temperature
    light.GetPrim().CreateAttribute("lumitrace:illuminant", Sdf.ValueTypeNames.String).Set(
        f"daylight {max(cct, 4000.0):g}")
    assert _cct(np.asarray(read(stage).emitters[0].spectrum)) == pytest.approx(
        max(cct, 4000.0), abs=10.0)


def test_a_sampled_spectrum_and_a_named_light_source(tmp_path):
    stage, light = _light(tmp_path, **{"lumitrace:spectrum": (
        Sdf.ValueTypeNames.Float2Array, [Gf.Vec2f(440, 1.0), Gf.Vec2f(460, 1.0)])})
    spd = np.asarray(read(stage).emitters[0].spectrum)
    assert spd[spectra.WAVELENGTHS == 450] == 1.0 and spd[spectra.WAVELENGTHS < 440].max() == 0
    light.GetPrim().GetAttribute("lumitrace:spectrum").Clear()
    light.GetPrim().CreateAttribute("lumitrace:illuminant", Sdf.ValueTypeNames.String).Set("LED-B3")
    import colour

    want = colour.SDS_ILLUMINANTS["LED-B3"].copy().align(spectra._shape()).values
    assert np.allclose(read(stage).emitters[0].spectrum, want)


def test_a_coloured_usdlux_colour_is_d65_tinted(tmp_path):
    stage, light = _light(tmp_path)
    light.CreateColorAttr(Gf.Vec3f(1.0, 0.5, 0.2))
    spd = np.asarray(read(stage).emitters[0].spectrum)
    xyz = spectra.tristimulus(spd)
    rgb = np.linalg.solve(np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722],
                                    [0.0193, 0.1192, 0.9505]]), xyz / xyz[1])
    assert rgb / rgb.max() == pytest.approx([1.0, 0.5, 0.2], abs=0.02)
    light.CreateColorAttr(Gf.Vec3f(0.5, 0.5, 0.5))  # grey: dimmer, not coloured
    assert read(stage).emitters[0].spectrum == ()


@pytest.mark.parametrize("name, kind, value, fragment", [
    ("lumitrace:spectrum", Sdf.ValueTypeNames.Float2Array, [Gf.Vec2f(500, 1)], "two"),
    ("lumitrace:spectrum", Sdf.ValueTypeNames.Float2Array,
     [Gf.Vec2f(500, 1), Gf.Vec2f(450, 1)], "increase"),
    ("lumitrace:spectrum", Sdf.ValueTypeNames.Float2Array,
     [Gf.Vec2f(500, -1), Gf.Vec2f(600, 1)], ">= 0"),
    ("lumitrace:spectrum", Sdf.ValueTypeNames.Float2Array,
     [Gf.Vec2f(900, 1), Gf.Vec2f(950, 1)], "no power"),
    ("lumitrace:spectrum", Sdf.ValueTypeNames.Float2Array,
     [Gf.Vec2f(500, float("nan")), Gf.Vec2f(600, 1)], "NaN"),
    ("lumitrace:illuminant", Sdf.ValueTypeNames.String, "candle", "unknown illuminant"),
    ("lumitrace:illuminant", Sdf.ValueTypeNames.String, "blackbody 300", "[1000, 25000]"),
])
def test_bad_light_colours_are_named(tmp_path, name, kind, value, fragment):
    stage, _ = _light(tmp_path, **{name: (kind, value)})
    message = expect_error(stage, fragment)
    assert "/Luminaire/Led" in message and name in message


def _surface(tmp_path, diffuse=(0.8, 0.8, 0.8), metallic=0.0, **attrs):
    stage = new_stage(tmp_path)
    add_disk(stage)
    mesh = add_mesh(stage, "/Luminaire/Part")
    mat = UsdShade.Material.Define(stage, "/Luminaire/Looks/Paint")
    shader = UsdShade.Shader.Define(stage, "/Luminaire/Looks/Paint/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*diffuse))
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(metallic)
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(mat)
    for name, (kind, value) in attrs.items():
        mat.GetPrim().CreateAttribute(name, kind).Set(value)
    return stage, mat


def test_a_grey_preview_surface_is_neutral(tmp_path):
    stage, _ = _surface(tmp_path)
    scene = read(stage)
    assert scene.materials[0].neutral and scene.colour == "none"


def test_a_coloured_preview_surface_gets_a_smooth_reflectance_of_its_albedo(tmp_path):
    stage, _ = _surface(tmp_path, diffuse=(0.7, 0.3, 0.1))
    m = read(stage).materials[0]
    assert not m.neutral and m.scattering == "diffuse"
    r = np.asarray(m.reflectance_spectrum)
    assert (r >= 0).all() and (r <= 1).all()
    assert r[spectra.WAVELENGTHS == 650] > 2 * r[spectra.WAVELENGTHS == 450]  # red
    w = spectra.d65() * spectra.observer()[:, 1]
    assert float(r @ w / w.sum()) == pytest.approx(m.reflectance, rel=1e-6)
    # a coloured metal tints its specular albedo instead
    stage, _ = _surface(tmp_path / "metal", diffuse=(0.95, 0.8, 0.4), metallic=1.0)
    m = read(stage).materials[0]
    assert m.specular_spectrum and not m.reflectance_spectrum


def test_authored_spectral_albedos_and_dispersion(tmp_path):
    pairs = [Gf.Vec2f(400, 0.2), Gf.Vec2f(700, 0.9)]
    stage, mat = _surface(tmp_path, **{
        "lumitrace:reflectanceSpectrum": (Sdf.ValueTypeNames.Float2Array, pairs)})
    m = read(stage).materials[0]
    r = np.asarray(m.reflectance_spectrum)
    assert r[0] == pytest.approx(0.2) and r[-1] == pytest.approx(0.9)  # held beyond
    assert r[spectra.WAVELENGTHS == 550][0] == pytest.approx(0.55)
    # a flat spectrum is its scalar: nothing spectral to trace
    mat.GetPrim().GetAttribute("lumitrace:reflectanceSpectrum").Set(
        [Gf.Vec2f(400, 0.4), Gf.Vec2f(700, 0.4)])
    m = read(stage).materials[0]
    assert m.neutral and m.reflectance == pytest.approx(0.4)
    # dispersion: Cauchy through n_d with the Abbe number
    mat.GetPrim().ApplyAPI("LumitraceMaterialAPI")
    mat.GetPrim().GetAttribute("lumitrace:scattering").Set("dielectric")
    mat.GetPrim().GetAttribute("lumitrace:ior").Set(1.49)
    mat.GetPrim().CreateAttribute("lumitrace:abbeNumber", Sdf.ValueTypeNames.Float).Set(57.0)
    m = read(stage).materials[0]
    n = m.spectrum("ior")
    at = lambda nm: float(np.interp(nm, spectra.WAVELENGTHS, n))  # noqa: E731
    assert at(587.56) == pytest.approx(1.49, abs=2e-4)
    assert (1.49 - 1.0) / (at(486.13) - at(656.27)) == pytest.approx(57.0, rel=2e-3)


def test_sellmeier_coefficients_give_a_glass_its_catalogue_indices(tmp_path):
    bk7 = [1.03961212, 0.231792344, 1.01046945, 0.00600069867, 0.0200179144, 103.560653]
    stage, mat = _surface(tmp_path, **{"lumitrace:sellmeier": (Sdf.ValueTypeNames.FloatArray,
                                                               bk7)})
    mat.GetPrim().ApplyAPI("LumitraceMaterialAPI")
    mat.GetPrim().GetAttribute("lumitrace:scattering").Set("dielectric")
    m = read(stage).materials[0]
    assert m.dispersive and not m.neutral
    n = m.spectrum("ior")
    at = lambda nm: float(np.interp(nm, spectra.WAVELENGTHS, n))  # noqa: E731
    # N-BK7's catalogue: n_d 1.5168, V_d 64.17 (float32 coefficients, 1 nm grid)
    assert at(587.56) == pytest.approx(1.5168, abs=2e-4)
    assert (at(587.56) - 1.0) / (at(486.13) - at(656.27)) == pytest.approx(64.17, rel=5e-3)
    bad = bk7[:3] + [0.5, 0.02, 103.0]  # a resonance at 707 nm, inside the visible
    mat.GetPrim().GetAttribute("lumitrace:sellmeier").Set(bad)
    expect_error(stage, "lumitrace:sellmeier", "380-780 nm")
    mat.GetPrim().GetAttribute("lumitrace:sellmeier").Set(bk7[:5])
    expect_error(stage, "lumitrace:sellmeier", "six finite numbers")


@pytest.mark.parametrize("name, kind, value, fragment", [
    ("lumitrace:reflectanceSpectrum", Sdf.ValueTypeNames.Float2Array,
     [Gf.Vec2f(400, 0.2), Gf.Vec2f(700, 1.2)], "[0, 1]"),
    ("lumitrace:abbeNumber", Sdf.ValueTypeNames.Float, -3.0, ">= 1"),
])
def test_bad_surface_colours_are_named(tmp_path, name, kind, value, fragment):
    stage, _ = _surface(tmp_path, **{name: (kind, value)})
    message = expect_error(stage, fragment)
    assert "/Luminaire/Looks/Paint" in message and name in message


def test_colour_only_edits_of_lights_are_a_rescale(tmp_path):
    """Where no surface has a colour, a light's colour changes no photon's path: the
    edit's effect is a rescale, and the colour figures follow it without tracing."""
    from lumitrace.delta.effect import classify

    stage, light = _light(tmp_path)
    before = read(stage)
    light.CreateEnableColorTemperatureAttr(True)
    light.CreateColorTemperatureAttr(3000.0)
    after = read(stage)
    assert after.colour == "emitters"
    assert classify(before, after).kind == "flux"


def test_usdlux_light_colour_keeps_its_flux(tmp_path):
    stage, light = _light(tmp_path)
    flux = read(stage).emitters[0].flux
    light.CreateEnableColorTemperatureAttr(True)
    light.CreateColorTemperatureAttr(2700.0)
    assert read(stage).emitters[0].flux == flux
    assert isinstance(light, UsdLux.DiskLight)


def test_colour_science_loads_without_a_word_about_scipy(tmp_path):
    """SciPy is not a dependency and lumitrace uses none of colour-science's SciPy-based
    functions: a stage with colour traces without colour-science's note that it is absent."""
    import subprocess
    import sys

    code = ("import sys; sys.modules['scipy'] = None\n"
            "import warnings; warnings.simplefilter('always')\n"
            "from lumitrace.scene import spectra\n"
            "print(spectra.observer().shape)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120, check=True)
    assert p.stdout.strip() == "(401, 3)" and "SciPy" not in p.stderr, p.stderr
