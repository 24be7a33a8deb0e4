"""Samplers checked against their densities on the sphere (chi-square), and the RNG."""
import numpy as np
import pytest

from helpers.chi2 import sphere_chi2_pvalue, sphere_integral
from lumitrace.trace import rng
from lumitrace.scene.shaping import shaping_window
from lumitrace.trace.emission import emit
from lumitrace.trace.scattering import MaterialTable, scatter
from lumitrace.scene import Emitter, Material

N = 200_000
ALPHA = 1e-3


def _u(n, k=4, seed=1):
    return rng.uniforms(rng.stream_key(seed, 7), np.arange(n, dtype=np.int64), 0, k)


def test_uniforms_are_pure_functions_of_the_index():
    key = rng.stream_key(3, 11)
    idx = np.arange(1000, dtype=np.int64)
    a = rng.uniforms(key, idx, 5, 4)
    b = rng.uniforms(key, idx[::-1].copy(), 5, 4)
    for x, y in zip(a, b):
        assert np.array_equal(x, y[::-1])
        assert x.min() >= 0.0 and x.max() < 1.0
    c = rng.uniforms(rng.stream_key(4, 11), idx, 5, 4)
    assert not np.array_equal(a[0], c[0])


def test_uniforms_moments_and_independence():
    u = _u(400_000, 4)
    for x in u:
        assert abs(x.mean() - 0.5) < 4 * np.sqrt(1 / 12 / x.size)
        assert abs(x.var() - 1 / 12) < 1e-3
    c = np.corrcoef(np.stack(u))
    assert np.abs(c - np.eye(4)).max() < 0.01


def random_polarisation(d: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Unpolarised light: a uniformly random unit direction across each ``d`` (3, N)."""
    t = np.cross(d.T, np.where(np.abs(d[0:1].T) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(d.T, t)
    return (np.cos(np.pi * u)[:, None] * t + np.sin(np.pi * u)[:, None] * b).T


def smith_g1(cos_theta: np.ndarray, alpha: float) -> np.ndarray:
    """Smith masking G1 of the GGX distribution (0 below the surface): the reference."""
    c2 = np.clip(cos_theta * cos_theta, 1e-300, 1.0)
    return np.where(cos_theta > 0, 2.0 / (1.0 + np.sqrt(1.0 + alpha * alpha * (1 - c2) / c2)), 0.0)


def _emitter(kind, **kw):
    m = np.eye(4)
    return Emitter(path=f"/L/{kind}", kind=kind, flux=1000.0, to_world=m, **kw)


@pytest.mark.parametrize("kind", ["disk", "rect"])
def test_area_light_emits_lambertian_along_minus_z(kind):
    e = _emitter(kind, radius=0.05, width=0.1, height=0.2)
    p, d = (a.T for a in emit(e, rng.stream_key(0, e.key), np.arange(N, dtype=np.int64)))
    assert np.allclose(p[:, 2], 0.0)
    pv = sphere_chi2_pvalue(d, lambda w: np.maximum(-w[:, 2], 0) / np.pi)
    assert pv > ALPHA
    if kind == "disk":
        r2 = (p[:, 0] ** 2 + p[:, 1] ** 2) / 0.05**2
        assert r2.max() <= 1.0
        # uniform by area: r^2 / R^2 is uniform on [0, 1]
        h = np.histogram(r2, bins=20, range=(0, 1))[0]
        assert np.abs(h - N / 20).max() < 5 * np.sqrt(N / 20)


def test_sphere_light_is_isotropic_and_on_its_surface():
    e = _emitter("sphere", radius=0.01)
    p, d = (a.T for a in emit(e, rng.stream_key(0, e.key), np.arange(N, dtype=np.int64)))
    assert np.allclose(np.linalg.norm(p, axis=1), 0.01)
    assert (np.einsum("ij,ij->i", p, d) >= -1e-12).all()  # leaves the surface outward
    assert sphere_chi2_pvalue(d, lambda w: np.full(len(w), 1 / (4 * np.pi))) > ALPHA


def test_cylinder_light_emits_from_its_side():
    e = _emitter("cylinder", radius=0.01, length=0.2)
    p, d = (a.T for a in emit(e, rng.stream_key(0, e.key), np.arange(N, dtype=np.int64)))
    assert np.allclose(np.hypot(p[:, 1], p[:, 2]), 0.01)
    assert np.abs(p[:, 0]).max() <= 0.1
    # intensity of a Lambertian cylinder along the axis vanishes; perpendicular it peaks:
    # I(theta) from the x axis is proportional to sin(theta)
    pv = sphere_chi2_pvalue(d[:, [1, 2, 0]], lambda w: np.sqrt(1 - w[:, 2] ** 2) / np.pi**2)
    assert pv > ALPHA


@pytest.mark.parametrize("angle,soft,focus", [(30.0, 0.0, 0.0), (45.0, 0.5, 0.0), (90.0, 0.0, 3.0)])
def test_shaped_disk_follows_its_window(angle, soft, focus):
    e = _emitter("disk", radius=0.01, cone_angle=angle, cone_softness=soft, focus=focus)
    p, d = (a.T for a in emit(e, rng.stream_key(0, e.key), np.arange(N, dtype=np.int64)))
    th = np.arccos(np.clip(-d[:, 2], -1, 1))
    assert th.max() <= np.radians(angle) + 1e-9
    t = np.linspace(0, np.pi / 2, 20001)
    norm = np.trapezoid(np.cos(t) * shaping_window(t, angle, soft, focus) * np.sin(t), t) * 2 * np.pi

    def pdf(w):
        c = np.clip(-w[:, 2], 0, 1)
        return c * shaping_window(np.arccos(c), angle, soft, focus) * (w[:, 2] < 0) / norm

    assert sphere_chi2_pvalue(d, pdf, n_theta=48, sub=64) > ALPHA


def _scatter(mat: Material, cos_in: float, n=N):
    table = MaterialTable.from_materials((mat,))
    s = np.sqrt(1 - cos_in**2)
    d = np.tile([s, 0.0, -cos_in], (n, 1))
    ng = np.tile([0.0, 0.0, 1.0], (n, 1))
    pol = random_polarisation(d.T, _u(n, 1, seed=9)[0])
    out, alive, _ = scatter(table, np.zeros(n, np.int32), d.T, ng.T, _u(n, 4, seed=5), pol)
    return d, out.T, alive


def test_diffuse_albedo_and_lobe():
    _, out, alive = _scatter(Material("/m", "diffuse", reflectance=0.7), 0.6)
    assert abs(alive.mean() - 0.7) < 4 * np.sqrt(0.21 / N)
    assert sphere_chi2_pvalue(out[alive], lambda w: np.maximum(w[:, 2], 0) / np.pi) > ALPHA


def test_translucent_splits_reflection_and_transmission():
    _, out, alive = _scatter(Material("/m", "translucent", reflectance=0.3, transmittance=0.5), 0.8)
    up = alive & (out[:, 2] > 0)
    down = alive & (out[:, 2] < 0)
    assert abs(up.mean() - 0.3) < 4 * np.sqrt(0.21 / N)
    assert abs(down.mean() - 0.5) < 4 * np.sqrt(0.25 / N)
    assert sphere_chi2_pvalue(out[down], lambda w: np.maximum(-w[:, 2], 0) / np.pi) > ALPHA


def test_mixed_materials_keep_photon_order():
    """Photons hitting different models in one wave come back in their own order."""
    mats = (Material("/d", "diffuse", reflectance=0.5), Material("/m", "mirror"),
            Material("/g", "dielectric", ior=1.5))
    table = MaterialTable.from_materials(mats)
    n = 3000
    mat = np.arange(n, dtype=np.int32) % 3
    d = np.tile([[0.6], [0.0], [-0.8]], (1, n))
    ng = np.tile([[0.0], [0.0], [1.0]], (1, n))
    u = _u(n, 4, seed=3)
    pol = np.full((3, n), np.nan)
    out, alive, _ = scatter(table, mat, d, ng, u, pol)
    for k in range(3):
        sel = mat == k
        o1, a1, _ = scatter(table, mat[sel], d[:, sel], ng[:, sel], [x[sel] for x in u], pol[:, sel])
        assert np.array_equal(out[:, sel], o1) and np.array_equal(alive[sel], a1)
    assert np.allclose(out[:, mat == 1].T, [0.6, 0.0, 0.8])


def test_mirror_reflects_exactly():
    d, out, alive = _scatter(Material("/m", "mirror", specular_reflectance=0.9), 0.3, n=20000)
    assert np.allclose(out, d * [1, 1, -1])
    assert abs(alive.mean() - 0.9) < 4 * np.sqrt(0.09 / 20000)


@pytest.mark.parametrize("cos_in", [1.0, 0.5, 0.1])
def test_dielectric_fresnel_and_snell(cos_in):
    n = 1.5
    d, out, alive = _scatter(Material("/m", "dielectric", ior=n), cos_in)
    assert alive.all()
    refl = out[:, 2] > 0
    ci = cos_in
    ct = np.sqrt(1 - (1 - ci**2) / n**2)
    rs = ((ci - n * ct) / (ci + n * ct)) ** 2
    rp = ((n * ci - ct) / (n * ci + ct)) ** 2
    f = 0.5 * (rs + rp)
    assert abs(refl.mean() - f) < 4 * np.sqrt(f * (1 - f) / N) + 1e-12
    t = out[~refl]
    sin_t = np.hypot(t[:, 0], t[:, 1])
    assert np.allclose(sin_t * n, np.sqrt(1 - ci**2))
    assert np.allclose(np.linalg.norm(t, axis=1), 1.0)


def test_dielectric_total_internal_reflection_from_inside():
    n = 1.5
    table = MaterialTable.from_materials((Material("/m", "dielectric", ior=n),))
    c = 0.5  # 60 degrees inside glass, beyond the 41.8 degree critical angle
    d = np.tile([np.sqrt(1 - c * c), 0, c], (1000, 1))  # travelling up, hits the back face
    ng = np.tile([0.0, 0, 1], (1000, 1))  # outward normal points up: the photon is inside
    pol = random_polarisation(d.T, _u(1000, 1, seed=9)[0])
    out, alive, _ = scatter(table, np.zeros(1000, np.int32), d.T, ng.T, _u(1000), pol)
    out = out.T
    assert alive.all() and np.allclose(out, d * [1, 1, -1])


def _ggx_brdf_cos(wi, alpha, spec):
    """Reference f(wi, wo) cos(wo) of a GGX reflector with separable Smith G (per sr)."""
    def pdf(wo):
        h = wo + wi
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        c = h[:, 2]
        a2 = alpha * alpha
        dd = a2 / (np.pi * (c * c * (a2 - 1) + 1) ** 2)
        g = smith_g1(wi[:, 2], alpha) * smith_g1(wo[:, 2], alpha)
        return np.where(wo[:, 2] > 0, spec * dd * g / (4 * wi[:, 2]), 0.0)
    return pdf


@pytest.mark.parametrize("rough,cos_in", [(0.3, 0.8), (0.6, 0.4)])
def test_glossy_samples_ggx_reflection(rough, cos_in):
    alpha = rough**2
    d, out, alive = _scatter(Material("/m", "glossy", specular_reflectance=1.0, roughness=rough), cos_in)
    ref = _ggx_brdf_cos(-d[:1], alpha, 1.0)
    albedo = sphere_integral(ref, 2048, 1024)
    # the survival rate is the directional albedo and survivors follow f cos / albedo
    assert abs(alive.mean() - albedo) < 4 * np.sqrt(albedo * (1 - albedo) / N) + 2e-3
    pv = sphere_chi2_pvalue(out[alive], lambda w: ref(w) / albedo, n_theta=48, n_phi=64)
    assert pv > ALPHA


def test_polarised_reflectance_at_brewster_angle():
    """p-polarised light is not reflected at Brewster's angle; s-polarised light is, with R_s."""
    n_glass = 1.5
    theta_b = np.arctan(n_glass)
    ci = np.cos(theta_b)
    table = MaterialTable.from_materials((Material("/m", "dielectric", ior=n_glass),))
    m = 50_000
    d = np.tile([np.sin(theta_b), 0.0, -ci], (m, 1))
    ng = np.tile([0.0, 0, 1], (m, 1))
    s_dir = np.tile([0.0, 1.0, 0.0], (m, 1))  # perpendicular to the plane of incidence (xz)
    p_dir = np.cross(s_dir, d)
    out_p, _, _ = scatter(table, np.zeros(m, np.int32), d.T, ng.T, _u(m), p_dir.T)
    assert (out_p[2] < 0).all()  # every p photon is transmitted
    out_s, _, pol_s = scatter(table, np.zeros(m, np.int32), d.T, ng.T, _u(m), s_dir.T)
    out_s, pol_s = out_s.T, pol_s.T
    ct = np.sqrt(1 - np.sin(theta_b) ** 2 / n_glass**2)
    rs = ((ci - n_glass * ct) / (ci + n_glass * ct)) ** 2
    refl = out_s[:, 2] > 0
    assert abs(refl.mean() - rs) < 4.5 * np.sqrt(rs * (1 - rs) / m)
    assert np.allclose(np.abs(pol_s[:, 1]), 1.0)  # s stays s


@pytest.mark.parametrize("counter", [0, 5 * rng.DIMS_PER_BOUNCE])
def test_seeds_give_independent_poisson_counts(counter):
    """The judged errors take every cell's count as binomial: photons independent within a
    seed and between seeds. 200 seeds of 65,536 photons binned on 64 x 64 cells of a draw's
    pair (an emission's, a fifth bounce's): each seed's chi-square per degree of freedom has
    mean 1 and spread sqrt(2 / dof), none is an outlier for 200 seeds, and the seeds pooled
    are as Poisson as one (shared or shifted streams would pile up there)."""
    seeds, n, side = 200, 65_536, 64
    dof = side * side - 1
    expected = n / side ** 2
    idx = np.arange(n, dtype=np.int64)
    stats, pooled = [], np.zeros(side * side)
    for seed in range(1, seeds + 1):
        base = rng.photon_hash(rng.stream_key(seed, 0x5EED), idx)
        u, v = rng.uniforms_from(base, counter, 2)
        k = np.bincount((u * side).astype(np.int64) * side + (v * side).astype(np.int64),
                        minlength=side * side)
        pooled += k
        stats.append(((k - expected) ** 2 / expected).sum() / dof)
    stats = np.array(stats)
    spread = np.sqrt(2.0 / dof)
    assert abs(stats.mean() - 1.0) < 4.0 * spread / np.sqrt(seeds)
    assert 0.8 < stats.std() / spread < 1.25
    assert (stats - 1.0).max() / spread < 5.5
    e_pooled = seeds * expected
    assert abs(((pooled - e_pooled) ** 2 / e_pooled).sum() / dof - 1.0) < 5.0 * spread
