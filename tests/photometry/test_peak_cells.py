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


def _cells_within_every_plane(centre, radius_deg):
    """The cells within ``radius_deg`` of ``centre``, every cell of the sphere tested."""
    inside = peak._cell_directions() @ centre >= np.cos(np.radians(radius_deg))
    return np.flatnonzero(inside)


def test_cells_within_a_cap_are_every_cell_the_whole_sphere_finds():
    """The fit's cells, looked for in the gamma band and C planes a cap can reach, are
    those of the whole sphere: near the poles, across C 0/360 and anywhere at random."""
    rng = np.random.default_rng(11)
    centres = [peak._direction(c, g) for c, g in
               [(0.0, 0.0), (0.3, 1.0), (359.9, 20.0), (0.1, 90.0), (180.0, 179.5),
                (45.0, 9.9), (270.0, 170.1), (359.4, 60.0), (0.62, 45.0)]]
    centres += [peak._direction(c, g) for c, g in
                zip(rng.uniform(0, 360, 40), np.degrees(np.arccos(rng.uniform(-1, 1, 40))))]
    for centre in centres:
        for radius in (1.5, 3.0, 10.0, 20.0):
            got = peak._cells_within(centre, radius)
            np.testing.assert_array_equal(got, _cells_within_every_plane(centre, radius))


def test_tangent_basis_is_orthonormal():
    rng = np.random.default_rng(5)
    for p in [np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0]),
              *(v / np.linalg.norm(v) for v in rng.normal(size=(20, 3)))]:
        u, v = peak._tangent_basis(p)
        basis = np.stack([p, u, v])
        np.testing.assert_allclose(basis @ basis.T, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(np.cross(p, u), v, atol=1e-15)
