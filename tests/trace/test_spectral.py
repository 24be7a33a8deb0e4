"""Spectral photons: a neutral path keeps its light's colour exactly, a coloured integrating
sphere shifts it as its closed form says, a dispersive prism sends each band where Snell's
law does, and the X and Z tallies are as deterministic as the counts."""
import shutil

import numpy as np
import pytest
from pxr import Sdf, Usd

from lumitrace.film.accumulate import Accumulator
from lumitrace.photometry.colour import colour_over_angle, uv_prime
from lumitrace.run.session import TraceSettings, run
from lumitrace.scene import Emitter, Material, Scene, spectra
from lumitrace.stage.reader import read_stage
from lumitrace.trace.job import BatchJob
from lumitrace.trace.tracer import prepare, trace_batch
from helpers.paths import REFERENCE

LED = "Phosphor LED YAG"


def _spectral_fixed(tally):
    return tuple(np.asarray(a.dense() if hasattr(a, "dense") else a) for a in tally.xz)


def _cup(reflectance_spectrum=(), reflectance=0.8):
    """A 5-sided open box (opening up) around a point light: most light bounces."""
    s = 0.05
    quads = [[(-s, -s, -s), (s, -s, -s), (s, s, -s), (-s, s, -s)]]
    for a, b in (((-s, -s), (s, -s)), ((s, -s), (s, s)), ((s, s), (-s, s)), ((-s, s), (-s, -s))):
        quads.append([(*a, -s), (*b, -s), (*b, s), (*a, s)])
    tri = np.array([[q[0], q[1], q[2]] for q in quads] + [[q[0], q[2], q[3]] for q in quads])
    mat = Material("/M", "diffuse", reflectance=reflectance,
                   reflectance_spectrum=tuple(reflectance_spectrum))
    return tri, mat


def _scene(tri, mats, emitter, material_index=None):
    n = len(tri)
    return Scene(np.asarray(tri, float), np.zeros(n, np.int32) if material_index is None
                 else np.asarray(material_index, np.int32), np.zeros(n, np.int32),
                 tuple(mats), ("/Part",), (emitter,))


def _led_light(**kw):
    import colour

    spd = colour.SDS_LIGHT_SOURCES[LED].copy().align(spectra._shape()).values
    return Emitter(path="/L", kind="sphere", flux=1000.0, to_world=np.eye(4), radius=0.001,
                   treat_as_point=True, spectrum=tuple(spd), **kw)


def test_a_neutral_path_carries_exactly_its_lights_colour():
    """A surface whose spectrum is flat but for a ripple too small to matter still makes
    photons spectral: every escaping photon then has its light's X/Y and Z/Y to rounding."""
    e = _led_light()
    want = spectra.chromaticity_ratios(e.spectrum)
    flat = np.full(spectra.WAVELENGTHS.size, 0.7)
    flat[::2] += 1e-6
    # a surface that is neutral outright makes nothing spectral: the light's colour alone
    for spectrum, colour, tol in ((flat, "spectral", 1e-5), ((), "emitters", 1e-12)):
        tri, mat = _cup(spectrum, 0.7)
        scene = _scene(tri, [mat], e)
        assert scene.colour == colour
        acc = Accumulator(scene, 16)
        acc.add(trace_batch(prepare(scene), BatchJob(0, 0, 30_000, 3, 16)))
        xyz = acc.cell_tristimulus()
        seen = xyz[1] > 0
        assert np.abs(xyz[0][seen] / xyz[1][seen] - want[0]).max() < tol
        assert np.abs(xyz[2][seen] / xyz[1][seen] - want[1]).max() < tol


def test_spectral_tallies_are_the_same_for_any_batch_split_and_thread():
    e = _led_light()
    red = spectra.resample([380, 550, 600, 780], [0.1, 0.2, 0.8, 0.9], hold=True)
    tri, mat = _cup(red)
    scene = _scene(tri, [mat], e)
    ps = prepare(scene)
    whole = trace_batch(ps, BatchJob(0, 0, 30_000, 11, 16))
    acc = Accumulator(scene, 16)
    for first, n in ((0, 7_000), (7_000, 13_000), (20_000, 10_000)):
        acc.add(trace_batch(ps, BatchJob(0, first, n, 11, 16)))
    t = acc.emitters[0]
    for mine, theirs in zip(t.xz, _spectral_fixed(whole)):
        assert np.array_equal(mine, theirs)
    assert np.array_equal(t.counts, whole.counts)
    # and through a session with two threads and small batches
    a = run(scene, TraceSettings(photons=30_000, resolution=16, seed=11, threads=2,
                                 batch_size=4096)).accumulator
    assert all(np.array_equal(x, y) for x, y in zip(a.emitters[0].xz, t.xz))


def test_a_coloured_integrating_sphere_follows_its_closed_form(tmp_path):
    """Phi_out(lambda) = Phi(lambda) rho f / (1 - rho (1 - f)) for every wavelength: the
    escaping light's chromaticity follows, here shifted far from the source's."""
    path = tmp_path / "sphere.usda"
    shutil.copy(REFERENCE / "integrating_sphere.usda", path)
    stage = Usd.Stage.Open(str(path))
    exp = dict(stage.GetRootLayer().customLayerData["lumitrace:expectation"])
    wl = np.array([380.0, 780.0])
    rho = np.array([0.55, 0.85])  # a linear ramp: warmer at every bounce
    stage.GetPrimAtPath("/Luminaire/Materials/Wall").CreateAttribute(
        "lumitrace:reflectanceSpectrum", Sdf.ValueTypeNames.Float2Array).Set(
        [(float(a), float(b)) for a, b in zip(wl, rho)])
    stage.GetPrimAtPath("/Luminaire/Source").CreateAttribute(
        "lumitrace:illuminant", Sdf.ValueTypeNames.String).Set("daylight 6500")
    stage.Save()
    scene = read_stage(path)
    assert scene.colour == "spectral"
    result = run(scene, TraceSettings(photons=200_000, resolution=8, seed=2, threads=2))
    acc = result.accumulator
    f = float(exp["port_fraction"])
    r = spectra.resample(wl, rho, hold=True)
    s = np.asarray(scene.emitters[0].spectrum)
    out = (s * r * f / (1.0 - r * (1.0 - f))) @ spectra.observer()
    want = uv_prime(out)
    got = uv_prime(acc.cell_tristimulus().sum(axis=1))
    halves = [uv_prime(acc.cell_tristimulus(h).sum(axis=1)) for h in (0, 1)]
    sigma = 0.5 * np.hypot(*(halves[0] - halves[1]))
    source = uv_prime(spectra.tristimulus(s))
    shift = np.hypot(*(want - source))
    assert shift > 0.01  # far beyond the noise: the test can tell
    # 4 sigma, and 1e-4 for the tracer's 10 nm bands (a reflectance averaged over each)
    assert np.hypot(*(got - want)) < 4.0 * sigma + 1e-4
    # the luminous flux is the same closed form, weighted by the eye
    y = float(out[1] / spectra.tristimulus(s)[1]) * 1000.0
    assert acc.fluxes()["escaped"] == pytest.approx(y, rel=0.02)
    ph = colour_over_angle(acc)
    assert ph.total["uv"] == pytest.approx(list(got), abs=1e-12)


def _prism(apex_deg=30.0):
    """A triangular glass prism along Y: its top face at z = 0.5 is flat, its lower face
    tilted ``apex_deg`` from it, so a beam going down meets that face at ``apex_deg``."""
    t = np.tan(np.radians(apex_deg))
    a, b, c = (-1.0, 0.5), (1.0, 0.5), (1.0, 0.5 - 2.0 * t)
    ys = (-1.0, 1.0)
    v = lambda p, y: (p[0], y, p[1])  # noqa: E731
    tris = [[v(a, ys[0]), v(b, ys[0]), v(c, ys[0])], [v(a, ys[1]), v(b, ys[1]), v(c, ys[1])]]
    for p, q in ((a, b), (b, c), (c, a)):
        tris += [[v(p, ys[0]), v(q, ys[0]), v(q, ys[1])], [v(p, ys[0]), v(q, ys[1]), v(p, ys[1])]]
    tris = np.array(tris)
    centre = tris.reshape(-1, 3).mean(axis=0)
    for k, tri in enumerate(tris):  # outward, counter-clockwise: the glass's front is air
        n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        if n @ (tri.mean(axis=0) - centre) < 0:
            tris[k] = tri[[0, 2, 1]]
    return tris


def test_a_prism_sends_every_band_where_snells_law_does():
    ior_d, abbe, apex = 1.6, 30.0, 30.0
    glass = Material("/Glass", "dielectric", ior=ior_d, abbe_number=abbe)
    to_world = np.eye(4)
    to_world[:3, 3] = (0.0, 0.0, 1.0)
    e = Emitter(path="/L", kind="disk", flux=1.0, to_world=to_world, radius=1e-4,
                cone_angle=1e-4)
    scene = _scene(_prism(apex), [glass], e)
    assert scene.colour == "spectral"
    ps = prepare(scene)
    tally = trace_batch(ps, BatchJob(0, 0, 40_000, 5, 16), records=True, exit_rays=True)
    rec = tally.records
    escaped = rec.texel >= 0
    d = tally.exit_rays[1]
    x_of = rec.x[escaped]
    # the band of every escaped photon, from its X (fixed point: X/Y of its band)
    w = ps.band_weights[0]
    band_x = np.rint(spectra.FIXED_POINT * w[0] / w[1]).astype(np.int64)
    n_bands = spectra.band_means(glass.spectrum("ior"))
    # leaving through the tilted face after crossing the top one: down and to +X
    through = (d[:, 2] < -0.5) & (d[:, 0] > 1e-3)
    outward = np.array([-np.sin(np.radians(apex)), 0.0, -np.cos(np.radians(apex))])
    bent = []
    for b in np.unique(x_of[through]):
        k = np.flatnonzero(band_x == b)
        if len(k) != 1:  # the red end's bands share one X/Y: not told apart
            continue
        k = int(k[0])
        # Snell: sin(theta_out) = n sin(apex) about the face's outward normal, for the
        # photons that crossed the top face and left by the tilted one (the most common
        # direction; a few come out of the other faces after a reflection inside)
        sin_out = np.linalg.norm(np.cross(d[through & (x_of == b)], outward), axis=1)
        values, counts = np.unique(np.round(sin_out, 4), return_counts=True)
        main = np.abs(sin_out - values[np.argmax(counts)]) < 1e-3
        assert main.mean() > 0.85
        assert np.abs(sin_out[main] - n_bands[k] * np.sin(np.radians(apex))).max() < 5e-6
        bent.append((k, float(np.degrees(np.arcsin(sin_out[main].mean())))))
    assert len(bent) >= 25  # the beam is split into its bands
    bent.sort()
    angles = [a for _, a in bent]
    assert all(a > b for a, b in zip(angles, angles[1:]))  # blue bends most
    # the spread of the visible beam: n_F - n_C = (n_d - 1) / abbe
    assert angles[0] - angles[-1] > 1.0


def test_a_dispersive_prism_keeps_every_bands_share_of_the_light():
    """Picking one band at a dispersive surface is unbiased: the light through the prism
    keeps its light's colour (the glass is clear) up to the noise of the pick."""
    glass = Material("/Glass", "dielectric", ior=1.5, abbe_number=40.0)
    e = _led_light()
    to_world = np.eye(4)
    to_world[:3, 3] = (0.0, 0.0, 1.0)
    e = Emitter(path="/L", kind="disk", flux=1.0, to_world=to_world, radius=1e-3,
                spectrum=e.spectrum)
    scene = _scene(_prism(20.0), [glass], e)
    acc = Accumulator(scene, 16)
    acc.add(trace_batch(prepare(scene), BatchJob(0, 0, 60_000, 9, 16)))
    xyz = acc.cell_tristimulus().sum(axis=1)
    want = spectra.chromaticity_ratios(e.spectrum)
    assert xyz[0] / xyz[1] == pytest.approx(want[0], rel=0.02)
    assert xyz[2] / xyz[1] == pytest.approx(want[1], rel=0.03)
