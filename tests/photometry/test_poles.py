"""Gamma 0 and 180 are directions, not planes: one value each, the same in every C plane,
from the whole polar cap, equal to the cap's closed form within its error and no noisier
than the values next to it."""
from __future__ import annotations

import math
import shutil

import numpy as np
from helpers.points import read_points
import pytest
from helpers.paths import REFERENCE, ROOT

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)
from lumitrace.photometry.distribution import photometry_of
from lumitrace.photometry.lm63 import read_ies
from lumitrace.photometry.measured import measure_all
from lumitrace.publish.outputs import write_outputs
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage

GAMMAS = np.arange(0.0, 180.0 + 1e-9, 2.5)


@pytest.fixture(scope="module")
def disc():
    scene = read_stage(REFERENCE / "lambertian_disc.usda")
    return run(scene, TraceSettings(photons=2_000_000, resolution=8, seed=3, threads=2))


def test_the_nadir_of_a_grid_without_symmetry_is_one_cap_value(disc):
    grids = measure_all(disc.accumulator, GAMMAS, 15.0, ("none",))
    g = grids["none", None]
    assert np.all(g.candela[:, 0] == g.candela[0, 0]) and np.all(g.sigma[:, 0] == g.sigma[0, 0])
    # the cap reaches the midpoint to the next gamma: the mean of (1000 / pi) cos over it
    h = math.radians(GAMMAS[1] / 2)
    cap = 1000.0 / math.pi * (1.0 + math.cos(h)) / 2.0
    assert abs(g.candela[0, 0] - cap) < 3.5 * g.sigma[0, 0], (g.candela[0, 0], cap)
    # 24 planes share it: the cap holds 24/8 = 3 times a neighbouring cell's solid angle
    assert g.sigma[0, 0] / g.candela[0, 0] < np.median(g.sigma[:, 1] / g.candela[:, 1])
    # the zenith of a one-sided disc: no light, no error
    assert g.candela[0, -1] == 0.0 and g.sigma[0, -1] == 0.0
    # each half's pole is one value too
    for h_ in (0, 1):
        half = measure_all(disc.accumulator, GAMMAS, 15.0, ("none",))["none", h_]
        assert np.all(half.candela[:, 0] == half.candela[0, 0])


def test_the_louvres_files_have_one_nadir_no_noisier_than_twice_the_median(tmp_path):
    stage = tmp_path / "louvre.usda"
    shutil.copy(ROOT / "stages" / "louvre.usda", stage)
    result = run(read_stage(stage), TraceSettings(photons=1_500_000, resolution=16, seed=4,
                                                  threads=2))
    ph = photometry_of(result.scene, result.accumulator)
    g = ph.grid
    assert g.symmetry != "rotational"  # the planes differ, the pole does not
    full = g.full()
    lit = full.candela > 0.1 * full.candela.max()
    median = np.median((full.sigma / np.where(lit, full.candela, 1.0))[lit])
    assert g.sigma[0, 0] / g.candela[0, 0] <= 2.0 * median
    record = write_outputs(result, tmp_path / "out", pictures=False, sublayer=False)
    ies = read_ies(record["ies"])
    assert len(ies.horizontal) > 1 and np.all(ies.candela[:, 0] == ies.candela[0, 0])


def _lambert(g: np.ndarray) -> np.ndarray:
    """A downward 1000 lm Lambertian disc's intensity (cd) at gamma ``g`` (rad)."""
    return np.where(g < math.pi / 2, 1000.0 / math.pi * np.cos(g), 0.0)


def test_the_rotational_discs_nadir_is_its_caps_mean_and_no_noisier_than_the_rest(disc):
    ph = photometry_of(disc.scene, disc.accumulator)
    g = ph.grid
    assert g.symmetry == "rotational"
    cap = g.pole_caps[0]
    # whole rings beside it: the first cap (1.25 deg) would be ~8 times noisier than the
    # median, so the cap widened (0.5 deg steps) to no more than 1.5 times
    assert 1.25 < cap <= 15.0
    lit = g.candela[0, 1:-1] >= 0.1 * g.candela.max()
    median = np.median(g.sigma[0, 1:-1][lit] / g.candela[0, 1:-1][lit])
    assert g.sigma[0, 0] / g.candela[0, 0] <= 1.5 * median + 1e-12
    expected = read_points(_lambert, g.gamma, g.pole_caps)
    assert abs(g.candela[0, 0] - expected[0]) < 3.5 * g.sigma[0, 0]
    assert abs(expected[0] / (1000.0 / math.pi) - 1.0) < 1e-4  # the fit: the nadir itself
    # every value of the file the engineer reads carries it, in every plane
    for full in (g.full(),):
        assert np.all(full.candela[:, 0] == g.candela[0, 0])


def test_every_file_value_poles_included_has_z_scores_of_unit_variance(disc):
    # 24 planes (15 deg) without symmetry: 900 lit values, the cells of a real file
    grids = measure_all(disc.accumulator, GAMMAS, 15.0, ("none", "rotational"))
    z = []
    for name in ("none", "rotational"):
        g = grids[name, None]
        rows = g.candela[:-1] if name == "none" else g.candela  # 360 repeats 0
        sig = g.sigma[:-1] if name == "none" else g.sigma
        expected = read_points(_lambert, g.gamma, g.pole_caps)
        ok = sig > 0
        zz = ((rows - expected) / np.where(ok, sig, 1.0))
        zz[:, [0, -1]] = np.nan
        z.append(zz[ok & ~np.isnan(zz)])
        pole_sig = sig[0, 0]
        z.append(np.array([(rows[0, 0] - expected[0]) / pole_sig]))  # each pole once
    z = np.concatenate(z)
    assert len(z) > 850
    assert abs(z.mean()) < 4.0 / math.sqrt(len(z)) + 0.03, z.mean()
    assert 0.85 < z.var() < 1.15, z.var()
    # the zenith is dark: exactly zero, no error
    assert grids["rotational", None].candela[0, -1] == 0.0


def test_the_demos_nadir_is_one_value_no_noisier_than_twice_the_median(tmp_path):
    result = run(read_stage(ROOT / "stages" / "downlight.usda"),
                 TraceSettings(photons=1_000_000, resolution=8, seed=6, threads=2))
    g = photometry_of(result.scene, result.accumulator).grid
    full = g.full()
    assert np.all(full.candela[:, 0] == full.candela[0, 0])
    lit = full.candela[:, 1:-1] >= 0.1 * full.candela.max()
    median = np.median(full.sigma[:, 1:-1][lit] / full.candela[:, 1:-1][lit])
    assert g.sigma[0, 0] / g.candela[0, 0] <= 2.0 * median
