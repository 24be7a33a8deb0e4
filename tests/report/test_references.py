"""Closed-form references (lumitrace.report.references) and the expectations stored in the stages."""
from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import integrate

from helpers.paths import REFERENCE
from lumitrace.report.references import (expected_figures, expected_intensity, fresnel_reflectance_sp,
                                  fresnel_unpolarised, lambertian_slab_flux, read_expectation,
                                  slab_transmittance)

STAGE_KINDS = {
    "isotropic.usda": "isotropic",
    "lambertian_disc.usda": "lambertian",
    "integrating_sphere.usda": "integrating_sphere",
    "fresnel_slab.usda": "fresnel_slab",
    "paraboloid.usda": "paraboloid",
}


def sphere_quadrature(n_mu: int = 64, n_phi: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Directions (N, 3) and solid-angle weights (N,) in sr, Gauss-Legendre in cos(theta)
    on each hemisphere separately (exact for piecewise polynomials with a kink at z = 0)."""
    x, w = np.polynomial.legendre.leggauss(n_mu)
    mu = np.concatenate([(x - 1) / 2, (x + 1) / 2])
    wmu = np.concatenate([w / 2, w / 2])
    phi = 2 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    M, P = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - M * M)
    dirs = np.stack([s * np.cos(P), s * np.sin(P), M], axis=-1).reshape(-1, 3)
    weights = (wmu[:, None] * np.full(n_phi, 2 * np.pi / n_phi)[None, :]).ravel()
    return dirs, weights


# -- Fresnel ---------------------------------------------------------------------------------
@pytest.mark.parametrize("n1, n2", [(1.0, 1.5), (1.5, 1.0), (1.0, 2.4), (1.33, 1.0)])
def test_fresnel_normal_incidence(n1, n2):
    assert_allclose(fresnel_unpolarised(1.0, n1, n2), ((n2 - n1) / (n2 + n1)) ** 2, rtol=1e-12)
    Rs, Rp = fresnel_reflectance_sp(1.0, n1, n2)
    assert_allclose(Rs, Rp, rtol=1e-12)


@pytest.mark.parametrize("n1, n2", [(1.0, 1.5), (1.5, 1.0), (1.0, 1.33)])
def test_brewster_angle_has_no_p_reflection(n1, n2):
    theta_b = math.atan(n2 / n1)
    Rs, Rp = fresnel_reflectance_sp(math.cos(theta_b), n1, n2)
    assert Rp == pytest.approx(0.0, abs=1e-15)
    assert Rs > 0.01


def test_fresnel_known_values_and_limits():
    # s and p at 45 deg, air to n = 1.5 (Hecht): R_s = 0.0920, R_p = 0.00846.
    Rs, Rp = fresnel_reflectance_sp(math.cos(math.radians(45)), 1.0, 1.5)
    assert_allclose([Rs, Rp], [0.092013, 0.0084663], rtol=1e-4)
    # grazing incidence reflects everything; beyond the critical angle too (glass to air).
    assert fresnel_unpolarised(0.0, 1.0, 1.5) == pytest.approx(1.0)
    critical = math.asin(1 / 1.5)
    assert_allclose(fresnel_unpolarised(math.cos(critical + 0.01), 1.5, 1.0), 1.0)
    assert fresnel_unpolarised(math.cos(critical - 0.01), 1.5, 1.0) < 1.0
    # no interface, no reflection
    assert_allclose(fresnel_unpolarised(np.linspace(0.01, 1, 7), 1.2, 1.2), 0.0, atol=1e-15)


def test_fresnel_is_reciprocal():
    ci = np.linspace(0.05, 1.0, 20)
    n = 1.5
    ct = np.sqrt(1 - (1 - ci ** 2) / n ** 2)       # refracted cosine inside the glass
    assert_allclose(fresnel_unpolarised(ci, 1.0, n), fresnel_unpolarised(ct, n, 1.0),
                    rtol=1e-12)


# -- slab --------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [1.33, 1.5, 2.0])
def test_slab_normal_incidence(n):
    assert_allclose(slab_transmittance(1.0, n), 2 * n / (n * n + 1), rtol=1e-12)


def test_slab_sums_inner_reflections():
    ci = np.linspace(0.0, 1.0, 11)
    Rs, Rp = fresnel_reflectance_sp(ci, 1.0, 1.5)
    k = np.arange(200)[:, None]
    series = [((1 - R) ** 2 * (R ** (2 * k))).sum(axis=0) for R in (Rs, Rp)]
    assert_allclose(slab_transmittance(ci, 1.5), 0.5 * (series[0] + series[1]), atol=1e-12)
    assert slab_transmittance(0.0, 1.5) == pytest.approx(0.0)
    assert_allclose(slab_transmittance(ci, 1.0), 1.0)


def test_lambertian_slab_flux_matches_quadrature():
    t, r = lambertian_slab_flux(1.5)
    ref, _ = integrate.quad(lambda g: slab_transmittance(math.cos(g), 1.5)
                            * 2 * math.cos(g) * math.sin(g), 0, math.pi / 2, epsabs=1e-12)
    assert_allclose(t, ref, rtol=1e-7)
    assert_allclose(t + r, 1.0)


# -- distributions -------------------------------------------------------------------------
def test_isotropic_and_lambertian_integrate_to_flux():
    dirs, w = sphere_quadrature()
    iso = {"kind": "isotropic", "flux": 1000.0}
    assert_allclose(expected_intensity(iso, dirs), 1000 / (4 * math.pi))
    assert_allclose(expected_intensity(iso, dirs) @ w, 1000.0, rtol=1e-12)
    lam = {"kind": "lambertian", "flux": 1000.0, "axis": [0.0, 0.0, -1.0]}
    intensity = expected_intensity(lam, dirs)
    assert_allclose(intensity @ w, 1000.0, rtol=1e-12)
    assert np.all(intensity[dirs[:, 2] > 0] == 0)
    assert_allclose(expected_intensity(lam, [[0, 0, -2.0]]), [1000 / math.pi])


def test_lambertian_axis_is_honoured():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(100, 3))
    lam = {"kind": "lambertian", "flux": 500.0, "axis": [1.0, 0.0, 0.0]}
    c = d[:, 0] / np.linalg.norm(d, axis=1)
    assert_allclose(expected_intensity(lam, d), 500 / math.pi * np.clip(c, 0, None))


def test_fresnel_slab_integrates_to_flux():
    dirs, w = sphere_quadrature(n_mu=400, n_phi=8)
    exp = {"kind": "fresnel_slab", "flux": 1000.0, "ior": 1.5, "axis": [0.0, 0.0, -1.0]}
    intensity = expected_intensity(exp, dirs)
    down = dirs[:, 2] < 0
    t, r = lambertian_slab_flux(1.5)
    assert_allclose(intensity[down] @ w[down], 1000.0 * t, rtol=1e-6)
    assert_allclose(intensity[~down] @ w[~down], 1000.0 * r, rtol=1e-5)
    assert_allclose(intensity @ w, 1000.0, rtol=1e-6)
    peak = 1000 / math.pi
    assert_allclose(expected_intensity(exp, [[0, 0, -1.0], [0, 0, 1.0]]),
                    [peak * 2 * 1.5 / 3.25, peak * (1 - 2 * 1.5 / 3.25)], rtol=1e-12)


def test_unknown_or_figure_only_kinds_are_refused():
    with pytest.raises(ValueError, match="expected_figures"):
        expected_intensity({"kind": "paraboloid", "flux": 1.0}, [[0, 0, -1.0]])
    with pytest.raises(ValueError, match="unknown"):
        expected_intensity({"kind": "nope", "flux": 1.0}, [[0, 0, -1.0]])
    with pytest.raises(ValueError, match="shape"):
        expected_intensity({"kind": "isotropic", "flux": 1.0}, [0, 0, -1.0])


# -- stored expectations --------------------------------------------------------------------
@pytest.mark.parametrize("name, kind", sorted(STAGE_KINDS.items()))
def test_stage_expectations_agree_with_closed_forms(name, kind):
    exp = read_expectation(REFERENCE / name)
    assert exp["kind"] == kind
    assert exp["flux"] == 1000.0
    assert isinstance(exp["description"], str) and exp["description"].endswith(".")
    figures = expected_figures(exp)
    for key, value in figures.items():
        if key in exp:
            assert_allclose(value, exp[key], rtol=1e-9, err_msg=key)
    if kind in ("lambertian", "fresnel_slab", "paraboloid"):
        assert exp["axis"] == [0.0, 0.0, -1.0]


def test_stage_expectation_figures_are_plausible():
    sphere = read_expectation(REFERENCE / "integrating_sphere.usda")
    assert 0.02 <= sphere["port_fraction"] <= 0.05
    assert sphere["port_fraction"] == pytest.approx(sphere["port_fraction_smooth"], rel=1e-3)
    assert sphere["port_axis"] == [0.0, 0.0, -1.0]
    assert_allclose(expected_figures(sphere)["escaped_flux"], 1000 * 0.9 * sphere["port_fraction"]
                    / (1 - 0.9 * (1 - sphere["port_fraction"])))
    para = read_expectation(REFERENCE / "paraboloid.usda")
    f, rim = para["focal_length"], para["rim_radius"]
    opening = math.degrees(math.atan2(rim, rim * rim / (4 * f) - f))
    assert para["opening_half_angle_deg"] == pytest.approx(opening)
    assert para["mirror_flux_fraction"] == pytest.approx(
        (1 + math.cos(math.radians(opening))) / 2, rel=1e-3)
    assert 0 < para["beam_half_angle_deg"] <= 5
    fig = expected_figures(para)
    assert fig["direct_cd"] == pytest.approx(1000 / (4 * math.pi))
    assert fig["escaped_flux"] < 1000


def test_read_expectation_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_expectation(tmp_path / "missing.usda")
    plain = tmp_path / "plain.usda"
    plain.write_text('#usda 1.0\n\ndef Xform "Luminaire"\n{\n}\n')
    with pytest.raises(KeyError, match="lumitrace:expectation"):
        read_expectation(plain)
