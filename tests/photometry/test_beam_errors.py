"""The beam and field angles' stated errors are honest where the profile's two sides are the
same values (a symmetric grid): measured grids drawn around a closed-form Lambertian
profile, their angles' spread against the errors stated for each; a rotationally symmetric
luminaire has one beam angle in every plane."""
from __future__ import annotations

import numpy as np
import pytest

from lumitrace.photometry import quantities
from lumitrace.photometry.grid import CGammaGrid
from lumitrace.photometry.peak import Peak
from lumitrace.photometry.quantities import PROFILE_GAMMAS, plane_spreads, redrawn
from helpers.traced import traced

PEAK = 1000.0 / np.pi  # cd, a 1000 lm Lambertian disc


def _grid(symmetry: str, values: np.ndarray, sigma: np.ndarray) -> CGammaGrid:
    c = {"rotational": np.array([0.0]), "none": np.arange(0.0, 360.0 + 1e-9, 5.0)}[symmetry]
    return CGammaGrid(c, PROFILE_GAMMAS, np.broadcast_to(values, (len(c), len(values))).copy(),
                      symmetry, np.broadcast_to(sigma, (len(c), len(sigma))).copy())


def test_a_redraw_keeps_what_one_value_stands_for():
    g = np.radians(PROFILE_GAMMAS)
    truth = np.where(g < np.pi / 2, PEAK * np.cos(g), 0.0)
    grid = _grid("none", truth, np.full(len(g), 3.0))
    values = redrawn(grid, np.random.default_rng(1))
    np.testing.assert_array_equal(values[-1], values[0])  # 360 deg is plane 0
    assert np.all(values[:, 0] == values[0, 0]) and np.all(values[:, -1] == values[0, -1])
    assert np.std(values[1:-1, 1:90] - truth[1:90]) == pytest.approx(3.0, rel=0.05)


def test_stated_errors_match_the_spread_of_symmetric_grids(monkeypatch):
    """60 grids of a rotationally symmetric luminaire, each value off the closed form by its
    error (both sides of a plane's profile are one value): the beam and field angles'
    standard deviation over them is the mean error each states."""
    monkeypatch.setattr(quantities, "BOOTSTRAP_DRAWS", 120)
    g = np.radians(PROFILE_GAMMAS)
    truth = np.where(g < np.pi / 2, PEAK * np.cos(g), 0.0)
    sigma = 0.004 * PEAK * np.sqrt(np.maximum(truth / PEAK, 1e-3))  # photon noise's shape
    rng = np.random.default_rng(7)
    angles, errors = {0.5: [], 0.1: []}, {0.5: [], 0.1: []}
    for _ in range(60):
        observed = truth + sigma * rng.standard_normal(len(g))
        grid = _grid("rotational", observed, sigma)
        top = Peak(PEAK + 0.5 * rng.standard_normal(), 0.5, 0.0, 0.0)
        spreads = plane_spreads(grid, (grid, grid), rng, top, planes=(0.0,))
        for f in (0.5, 0.1):
            angle, err, _, _ = spreads[0.0, f]
            angles[f].append(angle)
            errors[f].append(err)
    for f, want in ((0.5, 120.0), (0.1, 2.0 * np.degrees(np.arccos(0.1)))):
        a = np.array(angles[f])
        assert a.mean() == pytest.approx(want, abs=3.0 * a.std(ddof=1) / np.sqrt(len(a)))
        ratio = a.std(ddof=1) / np.mean(errors[f])
        assert 0.75 < ratio < 1.3, (f, ratio)


def test_a_rotationally_symmetric_luminaire_has_one_beam_in_every_plane():
    """A rotational luminaire's peak is a ring in every plane: both planes take it as their
    level, so their angles and errors are the same numbers (the disc: rotational by its
    geometry)."""
    _, _, ph, _ = traced("disc")
    f = ph.figures
    assert (ph.grid.symmetry, ph.symmetry.source) == ("rotational", "geometry")
    assert (f.beam_angle_c0_c180, f.beam_angle_c0_c180_error) == \
        (f.beam_angle_c90_c270, f.beam_angle_c90_c270_error)
    assert (f.field_angle_c0_c180, f.field_angle_c0_c180_error) == \
        (f.field_angle_c90_c270, f.field_angle_c90_c270_error)


def test_the_bootstraps_normal_draws_are_standard_normal_and_reproducible():
    """The figures' own normal draws (hashed counters, Box-Muller): mean 0, variance 1,
    no skew or excess kurtosis, the normal's quantiles, successive draws uncorrelated; the
    same seed the same draws, another seed others."""
    import math

    from lumitrace.photometry.grid import NormalDraws

    n = 400_000
    d = NormalDraws(0)
    z = d.standard_normal((n // 2, 2))
    assert z.shape == (n // 2, 2) and isinstance(d.standard_normal(), float)
    z = z.ravel()
    se = 1.0 / math.sqrt(n)
    assert abs(z.mean()) < 4 * se
    assert abs(z.var() - 1.0) < 4 * math.sqrt(2.0) * se
    assert abs(np.mean(z ** 3)) < 4 * math.sqrt(15.0) * se  # skewness, var 15/n
    assert abs(np.mean(z ** 4) - 3.0) < 4 * math.sqrt(96.0) * se  # excess kurtosis, var 96/n
    for q in (-2.0, -1.0, 0.0, 0.5, 1.5, 2.5):
        p = 0.5 * (1.0 + math.erf(q / math.sqrt(2.0)))
        assert abs(np.mean(z <= q) - p) < 4 * math.sqrt(p * (1 - p) / n), q
    assert abs(np.corrcoef(z[:-1], z[1:])[0, 1]) < 4 * se
    np.testing.assert_array_equal(NormalDraws(0).standard_normal((n // 2, 2)).ravel(), z)
    assert not np.array_equal(NormalDraws(1).standard_normal((n // 2, 2)).ravel(), z)
