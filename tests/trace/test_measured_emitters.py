"""Lights shaped by measured profiles (UsdLuxShapingAPI shaping:ies:file): traced in free
space they give back the profile's intensities within their stated errors, in the light's
own frame (gamma 0 along local -Z, C 0 toward local +X), with ies:angleScale as UsdLux
defines it; the luminaire's own IES-shaped stand-in light reproduces its IES file."""
import math
import shutil

import numpy as np
from helpers.points import read_points
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdLux

from helpers.paths import ROOT
from lumitrace.errors import LumitraceError, StageError
from lumitrace.photometry.grid import CGammaGrid
from lumitrace.photometry.lm63 import format_ies
from lumitrace.photometry.measured import cell_fluxes, cell_solid_angle_grid, measure
from lumitrace.run.session import TraceSettings, run
from lumitrace.scene import Emitter, IesShaping, Scene
from lumitrace.stage.reader import read_stage

FLUX = 1000.0
GAMMAS = np.arange(0.0, 180.0 + 1e-9, 5.0)
C_STEP = 15.0


def _write_ies(path, profile, planes=(0.0,), step=0.5):
    """An IES file of ``profile(C, gamma)`` (deg -> cd) sampled on the given planes."""
    g = np.arange(0.0, 180.0 + 1e-9, step)
    c = np.asarray(planes, float)
    cd = profile(c[:, None], g[None, :]) * np.ones((len(c), len(g)))
    sym = "rotational" if len(c) == 1 else "none"
    path.write_text(format_ies(CGammaGrid(c, g, cd, sym), FLUX, 0.0, 0.0, 0.0, {}))
    return path


def _free_space(ies, kind="sphere", to_world=np.eye(4), **dims):
    dims = dims or ({"radius": 0.0, "treat_as_point": True} if kind == "sphere" else {})
    e = Emitter(path="/L", kind=kind, flux=FLUX, to_world=to_world, ies=ies, **dims)
    return Scene(np.zeros((0, 3, 3)), np.zeros(0, np.int32), np.zeros(0, np.int32), (), (),
                 (e,))


def _cell_means(profile, sub=96):
    """The profile's mean (cd) over every cell of the C 15 x gamma 5 grid."""
    edges = np.concatenate([[0.0], 0.5 * (GAMMAS[1:] + GAMMAS[:-1]), [180.0]])
    f = (np.arange(sub) + 0.5) / sub
    g = edges[:-1, None] + f[None, :] * np.diff(edges)[:, None]  # (zones, sub)
    w = np.sin(np.radians(g))
    c = np.arange(0.0, 360.0, C_STEP)[:, None] + (f - 0.5)[None, :] * C_STEP  # (planes, sub)
    v = profile(c[:, None, :, None] % 360.0, g[None, :, None, :])  # planes, zones, sub, sub
    v = v * np.ones(c.shape[:1] + g.shape[:1] + (sub, sub))
    return (v * w[None, :, None, :]).sum(axis=(2, 3)) / (w.sum(axis=1)[None, :] * sub)


def _assert_reproduces(scene, profile, photons=1_000_000, seed=3, sub=96):
    """Photon counts per cell against the profile's expected counts (Poisson): the scaled
    deviations of well-filled cells have zero mean and unit variance, no cell is far off."""
    r = run(scene, TraceSettings(photons=photons, resolution=16, seed=seed))
    got = measure(r.accumulator, GAMMAS, C_STEP).full()
    counts = cell_fluxes(r.accumulator, GAMMAS, C_STEP) / (FLUX / photons)
    omega = cell_solid_angle_grid(GAMMAS, C_STEP)
    want = _cell_means(profile, sub)
    lam = want * omega * (photons / float((want * omega).sum()))  # the light's flux, shaped
    # the poles are one cap each: their counts (all planes) against the cap's
    for zone in (0, -1):
        n_cap, lam_cap = counts[:, zone].sum(), lam[:, zone].sum()
        assert np.all(got.candela[:, zone] == got.candela[0, zone])
        assert abs(n_cap - lam_cap) <= 5 * np.sqrt(lam_cap) + 5, (zone, n_cap, lam_cap)
    lam = lam[:, 1:-1]
    n = np.round(counts[:, 1:-1])
    full = lam >= 20
    z = (n - lam)[full] / np.sqrt(lam[full])
    assert np.abs(z).max() < 5.0, np.abs(z).max()
    assert abs(np.mean(z)) < 0.2 and 0.6 < np.var(z) < 1.5, (np.mean(z), np.var(z))
    assert np.all(n[~full] <= lam[~full] + 5 * np.sqrt(lam[~full]) + 5)
    assert np.all(n[lam == 0] == 0)
    return got


def _c_phase(grid) -> float:
    """The direction (deg) of the first harmonic in C of the flux per plane."""
    c = np.radians(grid.c)
    w = (grid.candela * cell_solid_angle_grid(GAMMAS, C_STEP)).sum(axis=1)
    return math.degrees(math.atan2((w * np.sin(c)).sum(), (w * np.cos(c)).sum())) % 360.0


def cosine(c, g):
    return FLUX / math.pi * np.maximum(np.cos(np.radians(g)), 0.0)


def narrow_cone(c, g):
    """A 10 deg spot with a linear edge to 12 deg (what the file's interpolation holds)."""
    return 20_000.0 * np.clip((12.0 - g) / 2.0, 0.0, 1.0)


def asymmetric(c, g):
    """Brighter toward C 0, and some light upward (from 90 to 92 deg on a linear ramp, as
    the file, sampled every degree, holds it)."""
    down = np.maximum(np.cos(np.radians(g)), 0.0) * (1.0 + 0.8 * np.cos(np.radians(c)))
    return 200.0 * down + 20.0 * np.clip((g - 90.0) / 2.0, 0.0, 1.0)


@pytest.mark.parametrize("profile", [cosine, narrow_cone])
def test_a_rotational_profile_is_reproduced_in_free_space(tmp_path, profile):
    path = _write_ies(tmp_path / "p.ies", profile)
    _assert_reproduces(_free_space(IesShaping(str(path))), profile)


def test_an_asymmetric_profile_keeps_c0_toward_the_lights_local_x(tmp_path):
    planes = np.arange(0.0, 360.0, 5.0)
    path = _write_ies(tmp_path / "a.ies", asymmetric, planes, step=1.0)
    ies = IesShaping(str(path))
    got = _assert_reproduces(_free_space(ies), asymmetric)
    assert min(_c_phase(got), 360.0 - _c_phase(got)) < 2.0  # brightest toward local +X
    # turned 90 deg about its axis, the light's +X is the world's +Y: C 90
    turn = np.array([[0.0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    turned = _assert_reproduces(_free_space(ies, to_world=turn),
                                lambda c, g: asymmetric(c - 90.0, g), seed=4)
    assert abs(_c_phase(turned) - 90.0) < 2.0


def test_an_eulumdat_profile_is_read_by_its_extension(tmp_path):
    from lumitrace.photometry.eulumdat import write_ldt

    g = np.arange(0.0, 180.0 + 1e-9, 2.5)
    planes = np.arange(0.0, 360.0, 15.0)
    grid = CGammaGrid(planes, g, asymmetric(planes[:, None], g[None, :]), "none")
    dims = {k: 10.0 for k in ("length", "width", "height", "lum_length", "lum_width",
                              "lum_height")}
    path = write_ldt(tmp_path / "a.ldt", grid, FLUX, "test", dims, 0.9, 1.0)

    def file_profile(c, gamma):  # what the file holds: linear between planes and angles
        c, gamma = np.broadcast_arrays(np.mod(c, 360.0), gamma)
        per_plane = np.stack([np.interp(gamma, g, row) for row in grid.candela])
        pos = c / 15.0
        i0 = np.floor(pos).astype(int) % len(planes)
        t = pos - np.floor(pos)
        at = lambda i: np.take_along_axis(per_plane, i[None], axis=0)[0]  # noqa: E731
        return (1 - t) * at(i0) + t * at((i0 + 1) % len(planes))

    _assert_reproduces(_free_space(IesShaping(str(path))), file_profile, photons=400_000,
                       sub=24)


def test_a_disc_light_emits_its_profile_upward_too(tmp_path):
    """The profile is the light's whole distribution: a one-sided disc emits its upward
    part as well, from its surface."""
    planes = np.arange(0.0, 360.0, 5.0)
    path = _write_ies(tmp_path / "a.ies", asymmetric, planes, step=1.0)
    _assert_reproduces(_free_space(IesShaping(str(path)), kind="disk", radius=0.05),
                       asymmetric, seed=5)


def test_angle_scale_maps_angles_as_usdlux_defines(tmp_path):
    """gamma_ies = (gamma - 180) / (1 + s) + 180: with s = -0.5 a downward cosine lobe
    appears between 90 and 135 deg."""
    path = _write_ies(tmp_path / "p.ies", cosine)

    def scaled(c, g):
        gi = (g - 180.0) / 0.5 + 180.0
        return np.where(gi >= 0.0, cosine(c, gi), 0.0)

    _assert_reproduces(_free_space(IesShaping(str(path), angle_scale=-0.5)), scaled)


def test_a_file_that_is_no_ies_profile_is_one_clear_error(tmp_path):
    bad = tmp_path / "bad.ies"
    bad.write_text("IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 3 1 1 2 0 0 0\n1 1 0\n0 5\n")
    with pytest.raises(LumitraceError) as info:
        run(_free_space(IesShaping(str(bad))), TraceSettings(photons=1000, resolution=4))
    assert str(bad) in str(info.value) and "IES profile" in str(info.value)


def _stage_with_light(folder, ies_asset, flux=FLUX, radius=0.05, name="light"):
    stage = Usd.Stage.CreateNew(str(folder / f"{name}.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(root.GetPrim())
    disk = UsdLux.DiskLight.Define(stage, "/Luminaire/Light")
    disk.CreateRadiusAttr(radius)
    p = disk.GetPrim()
    p.AddAppliedSchema("LumitraceEmitterAPI")
    p.CreateAttribute("lumitrace:luminousFlux", Sdf.ValueTypeNames.Float).Set(flux)
    shaping = UsdLux.ShapingAPI.Apply(p)
    shaping.CreateShapingIesFileAttr(Sdf.AssetPath(ies_asset))
    shaping.CreateShapingIesNormalizeAttr(True)
    stage.Save()
    return folder / f"{name}.usda"


def test_the_stage_resolves_the_profile_beside_its_layer(tmp_path):
    _write_ies(tmp_path / "cos.ies", cosine)
    scene = read_stage(_stage_with_light(tmp_path, "./cos.ies"))
    (e,) = scene.emitters
    assert (e.ies.file, e.ies.angle_scale, e.ies.normalize) == (str(tmp_path / "cos.ies"),
                                                                 0.0, True)
    assert e.ies.stamp  # the file's size and time: a new file makes a new light
    with pytest.raises(StageError) as info:
        read_stage(_stage_with_light(tmp_path, "./missing.ies", name="missing"))
    assert "missing.ies" in str(info.value) and "shaping:ies:file" in str(info.value)


def test_the_luminaires_stand_in_light_reproduces_its_ies_file(tmp_path):
    """Trace the demo, put its IES-shaped stand-in light alone into a new stage, trace that:
    the two distributions agree within their stated errors."""
    from lumitrace.photometry.distribution import photometry_of
    from lumitrace.publish.outputs import write_outputs

    stage = tmp_path / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage)
    result = run(read_stage(stage), TraceSettings(photons=1_000_000, resolution=16, seed=1))
    (tmp_path / "out").mkdir()
    record = write_outputs(result, tmp_path / "out", sublayer=False, pictures=False)
    first = photometry_of(result.scene, result.accumulator)
    light = tmp_path / "alone"
    light.mkdir()
    shutil.copy(record["ies"], light / "luminaire.ies")
    alone = read_stage(_stage_with_light(light, "./luminaire.ies",
                                         flux=first.figures.luminous_flux))
    again = run(alone, TraceSettings(photons=1_000_000, resolution=16, seed=2))
    second = photometry_of(alone, again.accumulator)
    a, b = first.grid.full(), second.grid.full()
    assert np.array_equal(a.gamma, b.gamma) and np.array_equal(a.c, b.c)
    # the file holds point values; the stand-in emits their interpolant, which the point
    # values read back (each C cell's mean of it, at the listed gammas)
    want = _interpolant_points(a, b.pole_caps)
    s = np.sqrt(a.sigma**2 + b.sigma**2)
    # (a dark value, a thousandth of the top or less, holds a photon or two: its stated
    # error is its own count's, no measure of what it could have been)
    live = (s > 0) & (want > 1e-3 * want.max())
    z = (b.candela - want)[live] / s[live]
    assert np.abs(z).max() < 5.0 and np.var(z) < 1.5, (np.abs(z).max(), np.var(z))
    assert abs(second.figures.luminous_flux / first.figures.luminous_flux - 1) < 0.01


def _interpolant_points(grid, pole_caps, sub=64):
    """What the files' point values read from the intensity a reader interpolates from
    ``grid`` (linear in C and in gamma): at each listed gamma, over each plane's C cell
    (C +- half a step), through the same fit (helpers.points)."""
    g = grid.gamma
    f = (np.arange(sub) + 0.5) / sub
    step = 360.0 / len(grid.c)
    out = np.zeros_like(grid.candela)
    for i, c0 in enumerate(grid.c):
        row = grid.at(c0 + (f - 0.5) * step).mean(axis=0)  # linear in gamma, C averaged
        out[i] = read_points(lambda x: np.interp(np.degrees(x), g, row), g, pole_caps)
    return out
