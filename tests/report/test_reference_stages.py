"""Every reference stage traced and compared with its closed form.

Tolerances come from the statistics of the photon count used: texel counts are compared
with their expectations by a chi-square test (a correct tracer fails with probability
1e-4 whatever the seed; a wrong distribution fails with certainty), and scalar fluxes
within 4.5 standard errors of their binomial estimates.
"""
from __future__ import annotations

import numpy as np
import pytest
from helpers.reference import chi2_pvalue, expected_counts, trace

from lumitrace.film.cubemap import texel_directions, texel_solid_angles
from lumitrace.report.references import expected_figures

ALPHA = 1e-4


@pytest.mark.parametrize("name", ["isotropic", "lambertian_disc", "fresnel_slab"])
def test_distribution_matches_closed_form(name):
    n = 1_000_000
    scene, result, exp = trace(name, n)
    acc = result.accumulator
    counts = acc.counts()
    expected = expected_counts(exp, acc.resolution, n)
    assert chi2_pvalue(counts, expected) > ALPHA
    # the candela values themselves, where the texels have enough photons to compare
    intensity = acc.intensity()
    ref = expected * float(exp["flux"]) / n / texel_solid_angles(acc.resolution)
    well = expected > 400
    rel = (intensity[well] - ref[well]) / ref[well]
    assert np.abs(rel).max() < 5.5 / np.sqrt(400)
    assert abs(rel.mean()) < 4.5 / np.sqrt(expected[well].sum())


def test_isotropic_intensity_value():
    _, result, exp = trace("isotropic", 400_000, res=8)
    i = result.accumulator.intensity()
    # the mean over the sphere, weighted by solid angle, is flux / 4pi exactly
    mean = (i * texel_solid_angles(8)).sum() / (4 * np.pi)
    assert mean == pytest.approx(1000 / (4 * np.pi), rel=1e-12)
    assert exp["intensity_cd"] == pytest.approx(1000 / (4 * np.pi))


def test_lambertian_cosine_law_and_dark_upper_hemisphere():
    _, result, _ = trace("lambertian_disc", 1_000_000, res=16)
    acc = result.accumulator
    d = texel_directions(16)
    upper = d[..., 2] > 1e-9
    assert acc.counts()[upper].sum() == 0  # a one-sided disc sends nothing upward
    assert acc.fluxes()["escaped"] == pytest.approx(1000.0, rel=1e-12)


def test_fresnel_slab_transmitted_and_reflected_flux():
    n = 1_000_000
    _, result, exp = trace("fresnel_slab", n)
    fig = expected_figures(exp)
    acc = result.accumulator
    d = texel_directions(acc.resolution)
    flux = acc.texel_flux()
    down = flux[d[..., 2] < -1e-9].sum()
    up = flux[d[..., 2] > 1e-9].sum()
    assert down + up == pytest.approx(acc.fluxes()["escaped"], rel=1e-12)
    p = fig["transmitted_flux"] / 1000.0
    sigma = 1000.0 * np.sqrt(p * (1 - p) / n)
    assert abs(down - fig["transmitted_flux"]) < 4.5 * sigma
    assert abs(up - fig["reflected_flux"]) < 4.5 * sigma + 1e-9
    assert acc.fluxes()["absorbed"] == 0.0


def test_integrating_sphere_multiplier():
    n = 400_000
    _, result, exp = trace("integrating_sphere", n, res=8)
    fig = expected_figures(exp)
    f = result.accumulator.fluxes()
    p = fig["escaped_flux"] / 1000.0
    sigma = 1000.0 * np.sqrt(p * (1 - p) / n)
    assert abs(f["escaped"] - fig["escaped_flux"]) < 4.5 * sigma
    assert f["cut"] == 0.0
    assert f["escaped"] + f["absorbed"] == pytest.approx(f["emitted"], rel=1e-9)


def test_paraboloid_beam_and_direct_light():
    n = 1_000_000
    res = 32
    _, result, exp = trace("paraboloid", n, res=res)
    fig = expected_figures(exp)
    acc = result.accumulator
    d = texel_directions(res)
    gamma = np.degrees(np.arccos(np.clip(-d[..., 2], -1, 1)))
    flux = acc.texel_flux()
    beam_cone = gamma <= fig["beam_half_angle_deg"]
    # flux in the beam cone: the reflected beam plus the direct light in that cone
    cone_omega = texel_solid_angles(res)[beam_cone].sum()
    want = fig["beam_flux"] + fig["direct_cd"] * cone_omega
    p = want / 1000.0
    assert abs(flux[beam_cone].sum() - want) < 4.5 * 1000.0 * np.sqrt(p * (1 - p) / n)
    # between the beam and the rim, only the direct (isotropic) light of the source
    ring = (gamma > fig["beam_half_angle_deg"] + 5) & (gamma < fig["opening_half_angle_deg"] - 5)
    i = acc.intensity()[ring]
    expected = fig["direct_cd"] * texel_solid_angles(res)[ring] * n / 1000.0
    assert chi2_pvalue(acc.counts()[ring], expected) > ALPHA
    assert np.mean(i) == pytest.approx(fig["direct_cd"], rel=4.5 / np.sqrt(expected.sum()))
