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


def _street_light(path, forward=None):
    """A street light photometered as IES files have them (C0 along the road): a
    Lambertian disc tilted 40 deg toward +Y, the street side (C90); ``forward`` authored
    as lumitrace:bugForward."""
    from pxr import Sdf, Usd, UsdGeom, UsdLux

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    lum = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(lum.GetPrim())
    disk = UsdLux.DiskLight.Define(stage, "/Luminaire/Led")
    disk.CreateRadiusAttr(0.05)
    disk.AddRotateXOp().Set(40.0)  # its normal from -Z toward +Y
    disk.GetPrim().AddAppliedSchema("LumitraceEmitterAPI")
    disk.GetPrim().CreateAttribute("lumitrace:luminousFlux",
                                   Sdf.ValueTypeNames.Float).Set(10000.0)
    if forward is not None:
        lum.GetPrim().CreateAttribute("lumitrace:bugForward",
                                      Sdf.ValueTypeNames.Token).Set(forward)
    stage.GetRootLayer().Save()
    return path


def test_the_forward_direction_turns_the_zones(tmp_path):
    """C90 forward: the zones turned a quarter; the street light's light toward C90 is
    front light there, and C270 forward makes it back light: the zones swap exactly."""
    from lumitrace.run.session import TraceSettings, run
    from lumitrace.stage.reader import read_stage

    np.testing.assert_array_equal(bug.zones("C90").reshape(bug.N_C, -1),
                                  np.roll(bug.zones("C0").reshape(bug.N_C, -1),
                                          int(90 / bug.C_STEP), axis=0))
    scene = read_stage(_street_light(tmp_path / "street.usda"))
    acc = run(scene, TraceSettings(photons=100_000, resolution=8, threads=2)).accumulator
    c90, c270, c0 = (bug.bug_rating(acc, f) for f in ("C90", "C270", "C0"))
    for z in ("L", "M", "H", "VH"):
        assert c90.lumens["F" + z] == pytest.approx(c270.lumens["B" + z], abs=1e-9)
        assert c90.lumens["B" + z] == pytest.approx(c270.lumens["F" + z], abs=1e-9)
    front = sum(c90.lumens["F" + z] for z in ("L", "M", "H", "VH"))
    back = sum(c90.lumens["B" + z] for z in ("L", "M", "H", "VH"))
    assert front > 3 * back  # tilted toward the street: mostly front light
    # C0 forward splits it down the middle: a roadway rating read the wrong way
    assert c0.lumens["FH"] == pytest.approx(c0.lumens["BH"], rel=0.1)
    assert c90.b < c0.b or c90.lumens["BH"] < c0.lumens["BH"]
    assert (c90.forward, c90.as_dict()["bug_forward"]) == ("C90", "C90")
    with pytest.raises(ValueError, match="C0, C90, C180, C270"):
        bug.bug_rating(acc, "C45")


def test_the_stage_and_the_command_line_choose_the_forward_direction(tmp_path):
    """lumitrace:bugForward on the luminaire prim, validated; --bug-forward overrides it
    for one run and the record says which."""
    import json
    import subprocess
    import sys

    from lumitrace.errors import StageError
    from lumitrace.stage.reader import read_stage

    assert read_stage(_street_light(tmp_path / "a.usda", "C90")).info.bug_forward == "C90"
    assert read_stage(_street_light(tmp_path / "b.usda")).info.bug_forward == "C0"
    with pytest.raises(StageError, match="lumitrace:bugForward"):
        read_stage(_street_light(tmp_path / "c.usda", "sideways"))

    def trace(stage, *more):
        p = subprocess.run([sys.executable, "-m", "lumitrace", "trace", str(stage),
                            "--photons", "100000", "--resolution", "8", "--no-progress",
                            "--no-pictures", "--no-sublayer", "--json", *more],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        return json.loads(p.stdout.strip().splitlines()[-1])["photometry"]

    declared = trace(tmp_path / "a.usda")
    overridden = trace(tmp_path / "a.usda", "--bug-forward", "C270")
    assert (declared["bug_forward"], overridden["bug_forward"]) == ("C90", "C270")
    assert declared["bug_zone_lumens"]["FL"] == overridden["bug_zone_lumens"]["BL"]
