"""The peak's fits read a half's goniometer cells where they reach (each cell summed once):
the values equal, bit for bit, those of the whole sphere summed at once, on a luminaire of
many lights with sparse counts and on one light with dense ones."""
from __future__ import annotations

import numpy as np
import pytest

from lumitrace.film.goniometer import N_CELLS
from lumitrace.photometry import peak
from lumitrace.photometry.peak import HalfCells
from helpers.traced import traced


@pytest.mark.parametrize("name", ["louvre", "demo"])
def test_cells_read_where_a_fit_reaches_equal_the_whole_sphere(name, monkeypatch):
    acc = traced(name)[1].accumulator
    rng = np.random.default_rng(3)
    lit = np.flatnonzero(HalfCells(acc, 0)(np.arange(N_CELLS))[0] > 0)
    assert lit.size > 1000
    for half in (0, 1):
        monkeypatch.setattr(peak, "LAZY_EMITTERS", 0)  # every cell at once
        whole = HalfCells(acc, half)
        monkeypatch.setattr(peak, "LAZY_EMITTERS", 1 << 30)  # cells as they are asked for
        lazy = HalfCells(acc, half)
        # overlapping reads, as a fit's moves make them, then the rest of the sphere
        for cells in (np.sort(rng.choice(lit, 500, replace=False)), lit[:2000], lit[1000:3000],
                      np.arange(N_CELLS)):
            for a, b in zip(lazy(cells), whole(cells)):
                np.testing.assert_array_equal(a, b)
        flux, var = whole(lit)
        assert (flux > 0).sum() > 1000 and np.all((var > 0) == (flux > 0))
        assert np.all(var <= flux * flux)  # n (1 - n / N) <= n^2 for a count n >= 1
