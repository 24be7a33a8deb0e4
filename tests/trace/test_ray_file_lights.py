"""Lights that emit a TM-25 ray file (lumitrace:rayFile): photons start at the file's rays,
drawn by flux, in the light prim's frame, with the file's luminous flux; a Lambertian LED
ray set turned to face down traces as the Lambertian closed form."""
import math

import numpy as np
from helpers.points import read_points
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdLux

from lumitrace import tm25
from lumitrace.errors import StageError
from lumitrace.photometry.measured import measure
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage

GAMMAS = np.arange(0.0, 180.0 + 1e-9, 5.0)


def _lambertian_led(path, n=1_000_000, photometric=True, seed=5):
    """An LED as makers publish it: rays from a 1 mm disc around +Z (the LED's own axis),
    cosine-distributed, 0.0002 lm each."""
    r = np.random.default_rng(seed)
    rad, phi = np.sqrt(r.random(n)), 2 * np.pi * r.random(n)
    u, v = r.random(n), 2 * np.pi * r.random(n)
    dirs = np.column_stack([np.sqrt(u) * np.cos(v), np.sqrt(u) * np.sin(v), np.sqrt(1 - u)])
    rays = tm25.RayFile(positions=np.column_stack([rad * np.cos(phi), rad * np.sin(phi),
                                                   np.zeros(n)]).astype(np.float32),
                        directions=dirs.astype(np.float32),
                        flux=np.full(n, 2e-4, np.float32))
    data = tm25.format_tm25(rays)
    if not photometric:  # the luminous column relabelled as radiant flux (W)
        head = bytearray(data[:tm25.TEXT_END])
        head[tm25.FLAGS_AT + 8:tm25.FLAGS_AT + 20] = np.array([1, 0, 0], "<i4").tobytes()
        data = bytes(head) + data[tm25.TEXT_END:]
    path.write_bytes(data)
    return path


def _stage(folder, ray_asset, flux=None, turn=180.0, name="led"):
    path = folder / f"{name}.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.001)  # modelled in millimetres
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(root.GetPrim())
    light = UsdLux.SphereLight.Define(stage, "/Luminaire/LED")
    light.CreateRadiusAttr(0.5)
    UsdGeom.Xformable(light).AddRotateXOp().Set(turn)  # the LED's +Z to the light's -Z
    p = light.GetPrim()
    p.AddAppliedSchema("LumitraceEmitterAPI")
    p.CreateAttribute("lumitrace:rayFile", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(ray_asset))
    if flux is not None:
        p.CreateAttribute("lumitrace:luminousFlux", Sdf.ValueTypeNames.Float).Set(flux)
    stage.Save()
    return path


def test_a_lambertian_ray_set_faced_down_traces_as_the_closed_form(tmp_path):
    rays = 1_000_000
    _lambertian_led(tmp_path / "led.TM25RAY", n=rays)
    scene = read_stage(_stage(tmp_path, "./led.TM25RAY"))
    (e,) = scene.emitters
    assert e.rays == str(tmp_path / "led.TM25RAY")
    assert e.flux == pytest.approx(200.0, rel=1e-5)  # the file's luminous flux
    photons = 400_000
    r = run(scene, TraceSettings(photons=photons, resolution=16, seed=2))
    got = measure(r.accumulator, GAMMAS, 15.0, "rotational")
    g = np.radians(GAMMAS)
    # (flux / pi) cos(gamma) as the files' point values read it
    want = read_points(lambda x: np.where(x < np.pi / 2, e.flux / np.pi * np.cos(x), 0.0),
                       GAMMAS, got.pole_caps)
    sigma = got.sigma[0] * math.sqrt(1.0 + photons / rays)  # photons and the ray set's noise
    live = sigma > 0
    z = (got.candela[0] - want)[live] / sigma[live]
    assert np.abs(z).max() < 5.0, z
    assert np.all(got.candela[0][g > np.radians(92.5)] == 0)  # nothing goes up


def test_the_light_prims_frame_turns_the_rays(tmp_path):
    _lambertian_led(tmp_path / "led.TM25RAY", n=20_000)
    scene = read_stage(_stage(tmp_path, "./led.TM25RAY", turn=0.0))
    r = run(scene, TraceSettings(photons=20_000, resolution=8, seed=1))
    up = measure(r.accumulator, GAMMAS, 15.0, "rotational").candela[0]
    assert up[GAMMAS < 87.5].sum() == 0 and up[GAMMAS > 92.5].sum() > 0


def test_flux_and_errors(tmp_path):
    _lambertian_led(tmp_path / "w.TM25RAY", n=1000, photometric=False)
    with pytest.raises(StageError) as info:
        read_stage(_stage(tmp_path, "./w.TM25RAY"))
    assert "radiant flux only" in str(info.value) and "luminousFlux" in str(info.value)
    (e,) = read_stage(_stage(tmp_path, "./w.TM25RAY", flux=350.0, name="given")).emitters
    assert e.flux == 350.0
    with pytest.raises(StageError) as info:
        read_stage(_stage(tmp_path, "./nowhere.TM25RAY", name="missing"))
    assert "nowhere.TM25RAY" in str(info.value) and "lumitrace:rayFile" in str(info.value)


def test_rays_with_wavelengths_give_each_direction_its_colour(tmp_path):
    """A spectral ray file (a wavelength per ray): blue rays leave to one side, red ones to
    the other; each photon starts with its ray's colour, so each side has the chromaticity
    of its wavelength, and the light its mixture."""
    from lumitrace.photometry.colour import colour_over_angle, uv_prime
    from lumitrace.scene import spectra

    n = 4000
    side = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)  # blue to +X, red to -X
    a = np.radians(30.0)
    dirs = np.column_stack([side * np.sin(a), np.zeros(n), np.full(n, np.cos(a))])
    wl = np.where(side > 0, 450.0, 610.0)
    v = np.interp(wl, spectra.WAVELENGTHS, spectra.observer()[:, 1])
    lum = np.full(n, 0.25)  # equal luminous flux per ray: as much light each way
    rays = tm25.RayFile(positions=np.zeros((n, 3), np.float32),
                        directions=dirs.astype(np.float32), flux=lum.astype(np.float32),
                        wavelengths=wl.astype(np.float32),
                        radiant=(lum / (683.0 * v)).astype(np.float32))
    (tmp_path / "rgb.TM25RAY").write_bytes(tm25.format_tm25(rays))
    back = tm25.read_tm25(tmp_path / "rgb.TM25RAY")
    assert back.spectral_id == 2 and np.array_equal(back.wavelengths, wl.astype(np.float32))
    scene = read_stage(_stage(tmp_path, "./rgb.TM25RAY"))
    e = scene.emitters[0]
    assert e.ray_bands and scene.colour == "spectral" and e.flux == pytest.approx(1000.0)
    acc = run(scene, TraceSettings(photons=40_000, resolution=8, seed=2)).accumulator
    col = colour_over_angle(acc)
    cmf = spectra.observer()
    lit = col.xyz[1] > 0
    # the light points down after its turn: blue rays toward one C half, red the other
    uv = col.uv[:, lit].T
    want = {k: uv_prime(cmf[spectra.WAVELENGTHS == k][0]) for k in (450, 610)}
    near = [min(np.hypot(*(p - want[450])), np.hypot(*(p - want[610]))) for p in uv]
    assert max(near) < 1e-5  # every lit cell is one ray colour or the other, exactly
    blue = [np.hypot(*(p - want[450])) < 1e-5 for p in uv]
    flux = col.xyz[1][lit]
    share = flux[np.array(blue)].sum() / flux.sum()
    assert share == pytest.approx(0.5, abs=0.02)  # half the light each way
    total = acc.cell_tristimulus().sum(axis=1)
    mix = 0.5 * cmf[spectra.WAVELENGTHS == 450][0] / cmf[spectra.WAVELENGTHS == 450][0][1] \
        + 0.5 * cmf[spectra.WAVELENGTHS == 610][0] / cmf[spectra.WAVELENGTHS == 610][0][1]
    assert total[0] / total[1] == pytest.approx(mix[0] / mix[1], rel=0.02)


def test_a_radiometric_spectral_ray_file_has_its_luminous_flux(tmp_path):
    """Rays with wavelengths and radiant flux only: the light's flux is 683 lm/W times
    V(lambda) times the rays' radiant flux, and photons are drawn by it."""
    from lumitrace.scene import spectra

    n = 3000
    wl = np.where(np.arange(n) % 3 == 0, 555.0, 450.0).astype(np.float32)
    radiant = np.full(n, 1e-3, np.float32)
    dirs = np.tile(np.array([0.0, 0.0, 1.0], np.float32), (n, 1))
    rays = tm25.RayFile(positions=np.zeros((n, 3), np.float32), directions=dirs,
                        flux=radiant, wavelengths=wl, radiant=radiant)
    data = bytearray(tm25.format_tm25(rays))
    # relabel: radiant flux and wavelengths only (no luminous column): drop it
    flags = np.frombuffer(bytes(data[tm25.FLAGS_AT:tm25.FLAGS_AT + 32]), "<i4").copy()
    flags[4] = 0
    data[tm25.FLAGS_AT:tm25.FLAGS_AT + 32] = flags.tobytes()
    body = np.frombuffer(bytes(data[tm25.TEXT_END + 4:]), "<f4").reshape(n, 9)[:, :8]
    (tmp_path / "w.TM25RAY").write_bytes(bytes(data[:tm25.TEXT_END + 4]) + body.tobytes())
    scene = read_stage(_stage(tmp_path, "./w.TM25RAY"))
    v = np.interp(wl, spectra.WAVELENGTHS, spectra.observer()[:, 1])
    assert scene.emitters[0].flux == pytest.approx(683.0 * float((v * 1e-3).sum()), rel=1e-5)
