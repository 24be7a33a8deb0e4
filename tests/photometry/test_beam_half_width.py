"""The beam's half width, which chooses the files' gammas: read on what the photons show,
so a flat top (a cup's direct light, level to its cut-off) is as wide as its cut-off on
every seed, and a narrow beam on the axis is still found narrow."""
from __future__ import annotations

import numpy as np
import pytest

from lumitrace.film.goniometer import GAMMA_EDGES, cell_solid_angles
from lumitrace.photometry.distribution import beam_half_width
from lumitrace.photometry.grid import default_gammas


def _rings(intensity, photons: int, seed: int) -> list:
    """One emitter's rings (photon flux, photons, counts per gamma bin) for a profile
    ``intensity(gamma deg)`` (relative), ``photons`` of them drawn (multinomial)."""
    centres = 0.5 * (GAMMA_EDGES[1:] + GAMMA_EDGES[:-1])
    p = intensity(centres) * cell_solid_angles().sum(axis=0)
    counts = np.random.default_rng(seed).multinomial(photons, p / p.sum())
    return [(1000.0 / photons, photons, counts.astype(np.float64))]


def _flat_top(g):
    """The white cup's profile: level to its cut-off at 26.6 deg (a little lower within 6
    deg of the axis, as the cup's is), a fifth of that beyond."""
    return np.where(g < 26.6, np.where(g < 6.0, 0.9, 1.0), 0.2)


@pytest.mark.parametrize("photons", [250_000, 1_000_000])
def test_a_flat_top_is_as_wide_as_its_cut_off_on_every_seed(photons):
    widths = [beam_half_width(_rings(_flat_top, photons, seed)) for seed in range(12)]
    assert all(26.0 <= w <= 27.5 for w in widths), widths
    # so the files keep the default gammas, whatever the seed
    assert all(len(default_gammas(w)) == len(default_gammas(None)) for w in widths)


def test_a_narrow_beam_on_the_axis_is_found_narrow():
    def spot(g):  # halves at 5 deg
        return np.exp(-np.log(2.0) * (g / 5.0) ** 2)

    widths = [beam_half_width(_rings(spot, 1_000_000, seed)) for seed in range(6)]
    assert all(4.5 <= w <= 5.5 for w in widths), widths
    assert all(len(default_gammas(w)) > len(default_gammas(None)) for w in widths)


def test_noise_alone_makes_no_beam():
    """An isotropic source, few photons: no ring is surely below half of another."""
    widths = [beam_half_width(_rings(np.ones_like, 20_000, seed)) for seed in range(12)]
    assert widths == [None] * 12
