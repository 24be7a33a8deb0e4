"""The BUG rating (IES TM-15-11): zone lumens of an isotropic source and of a downward
Lambertian disc against the zone fluxes computed by hand, and the addendum's tables."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lumitrace.photometry import bug
from helpers.traced import traced


def _ring(flux_per_sr_fn, a: float, b: float) -> float:
    """Flux (lm) between gamma a and b (deg) all round, of I(gamma) given as the closed
    form of its integral over the zone."""
    return flux_per_sr_fn(math.radians(b)) - flux_per_sr_fn(math.radians(a))


def _by_hand(kind: str, flux: float) -> dict:
    # isotropic: I = flux / 4 pi, a ring holds flux / 2 (cos a - cos b);
    # Lambertian down: I = flux / pi cos g, a ring holds flux (sin^2 b - sin^2 a)
    prim = {"isotropic": lambda g: -0.5 * flux * math.cos(g),
            "disc": lambda g: flux * math.sin(min(g, math.pi / 2)) ** 2}[kind]
    down = dict(zip(("L", "M", "H", "VH"), zip(bug.DOWN_EDGES[:-1], bug.DOWN_EDGES[1:])))
    out = {}
    for side in "FB":  # each half of the ring
        for z, (a, b) in down.items():
            out[side + z] = 0.5 * _ring(prim, a, b)
    up = {"UL": (90.0, 100.0), "UH": (100.0, 180.0)}
    for z, (a, b) in up.items():
        out[z] = _ring(prim, a, b) if kind == "isotropic" else 0.0
    return out


@pytest.mark.parametrize("kind, rating", [("isotropic", "B0 U3 G1"), ("disc", "B1 U0 G1")])
def test_zone_lumens_match_the_closed_form(kind, rating):
    _, result, _, _ = traced(kind)
    r = bug.bug_rating(result.accumulator)
    want = _by_hand(kind, 1000.0)
    for z in bug.ZONES:
        if want[z] == 0.0:  # no photon goes there: exactly nothing, exactly no error
            assert r.lumens[z] == 0.0 and r.errors[z] == 0.0, z
        else:
            assert r.lumens[z] == pytest.approx(want[z], abs=4.0 * r.errors[z]), z
            assert 0.0 < r.errors[z] < 0.05 * want[z], z
    # the zones are every escaping photon, once
    assert sum(r.lumens.values()) == pytest.approx(result.accumulator.fluxes()["escaped"],
                                                   rel=1e-9)
    assert r.text == rating == "B{} U{} G{}".format(*bug.ratings(want))
    assert r.as_dict()["bug_rating"] == rating


def test_ratings_follow_the_addendum_tables():
    zero = {z: 0.0 for z in bug.ZONES}
    assert bug.ratings(zero) == (0, 0, 0)
    assert bug.ratings({**zero, "UL": 0.5}) == (0, 1, 0)  # any uplight at all: U1
    assert bug.ratings({**zero, "BM": 221.0}) == (1, 0, 0)
    assert bug.ratings({**zero, "BH": 111.0}) == (1, 0, 1)  # BH counts for B and G
    assert bug.ratings({**zero, "FH": 12001.0}) == (0, 0, 5)
    assert bug.ratings({**zero, "FVH": 750.0, "BL": 5000.0, "UH": 1000.0}) == (4, 4, 4)


def test_rating_range_shows_a_zone_near_a_limit():
    lumens = {z: 0.0 for z in bug.ZONES}
    errors = dict(lumens)
    lumens["BM"], errors["BM"] = 215.0, 5.0  # B0, but B1 within two standard errors
    r = bug.BugRating(*bug.ratings(lumens), lumens, errors,
                      bug.ratings({z: lumens[z] - 2 * errors[z] for z in bug.ZONES}),
                      bug.ratings({z: lumens[z] + 2 * errors[z] for z in bug.ZONES}))
    assert r.text == "B0 U0 G0" and r.range_text == "B0-1 U0 G0"


def test_zone_of_cell_edges():
    zone = bug.zone_of_cell().reshape(-1, len(bug.zone_of_cell()) // 288)
    assert zone.shape[0] == 288  # 1.25 deg C cells
    # C cells centred within 90 deg of C0 are forward, the others back
    assert set(np.unique(zone[0])) >= {0, 1, 2, 3, 8, 9}
    assert set(np.unique(zone[100])) >= {4, 5, 6, 7, 8, 9}


def test_zone_counts_of_dense_and_listed_cells_are_equal():
    """The dense counts' zones (C planes summed per side first) equal the cells' zones
    summed cell by cell, as the listed (sparse) counts are: exactly."""
    rng = np.random.default_rng(7)
    values = rng.integers(0, 50, bug.N_CELLS + 3).astype(np.uint32)
    idx = np.arange(bug.N_CELLS + 3)

    class Counts:
        def __init__(self, dense):
            self.dense = dense

        def emitter_cells(self):
            yield 0.01, 1e6, values, None if self.dense else idx

    dense, listed = bug.zone_lumens(Counts(True)), bug.zone_lumens(Counts(False))
    by_cell = np.bincount(bug.zone_of_cell(), weights=values[:bug.N_CELLS].astype(float),
                          minlength=len(bug.ZONES))
    assert np.array_equal(dense[0], listed[0]) and np.array_equal(dense[1], listed[1])
    assert np.array_equal(dense[0], 0.01 * by_cell)
