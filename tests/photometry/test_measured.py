"""The photometric files are measurements: every value agrees with the closed form of the
reference stages within its own stated standard error, at several photon counts, and the
stated errors are honest (their z-scores have unit variance)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from dataclasses import replace

from lumitrace.photometry import frame
from lumitrace.photometry.distribution import photometry_of
from lumitrace.photometry.eulumdat import read_ldt
from lumitrace.photometry.lm63 import read_ies
from lumitrace.publish.outputs import write_outputs
from lumitrace.report.references import expected_figures, expected_intensity, read_expectation
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage
from helpers.paths import REFERENCE
from helpers.points import read_points

#: Reference stages with a closed-form distribution, and the photon counts they are
#: checked at (seeds differ, so every run is independent).
CASES = [("lambertian_disc", (250_000, 1_000_000)), ("isotropic", (250_000, 1_000_000)),
         ("mirror_cup", (250_000, 1_000_000)), ("fresnel_slab", (200_000, 600_000))]


def point_truth(expectation: dict, grid) -> np.ndarray:
    """The closed form as the files' point values read it (cd per listed gamma), for the
    rotationally symmetric references (:func:`helpers.points.read_points`)."""
    def profile(g):
        d = frame.directions(np.zeros(g.size), np.degrees(g.ravel()), "Z")
        return expected_intensity(expectation, d).reshape(g.shape)

    return read_points(profile, grid.gamma, grid.pole_caps)


def z_scores(grid, truth: np.ndarray, photon_flux: float, averaged: int = 1) -> np.ndarray:
    """(value - truth) / sigma over the grid's cells with photons; cells without any must
    be cells the closed form expects (next to) nothing in."""
    sigma, value = grid.sigma, grid.candela
    omega_per = None
    empty = sigma == 0
    if empty.any():
        # an empty cell is fine only where the closed form expects few photons
        from lumitrace.photometry.measured import cell_solid_angle_grid
        omega_per = cell_solid_angle_grid(grid.gamma, 5.0)[0][None, :]
        expected_photons = np.broadcast_to(truth, value.shape) * omega_per / photon_flux
        expected_photons = expected_photons * averaged
        assert np.all(value[empty] == 0.0)
        assert expected_photons[empty].max(initial=0.0) < 10.0
    return ((value - truth) / np.where(empty, np.inf, sigma))[~empty]


@pytest.fixture(scope="module")
def measured():
    """Every case traced at every photon count: (name, photons, scene, result, grid, truth)."""
    out = []
    seed = 11
    for name, counts in CASES:
        stage = REFERENCE / f"{name}.usda"
        scene, expectation = read_stage(stage), read_expectation(stage)
        for photons in counts:
            seed += 1
            result = run(scene, TraceSettings(photons=photons, seed=seed, resolution=32))
            ph = photometry_of(scene, result.accumulator)
            truth = point_truth(expectation, ph.grid)
            out.append((name, photons, scene, result, ph, truth, expectation))
    return out


def test_every_value_within_four_of_its_standard_errors(measured):
    pooled = []
    for name, photons, scene, result, ph, truth, _ in measured:
        # the slab's square box shows a square's symmetry by its geometry, the others a
        # rotational one; the slab's counts may show rotational
        assert ph.symmetry.name == ("octant" if name == "fresnel_slab" else "rotational") \
            or ph.symmetry.source == "measured", (name, ph.symmetry)
        assert ph.symmetry.source in ("geometry", "measured")
        averaged = {"rotational": 72, "octant": 8}[ph.symmetry.name]
        grid = ph.grid
        if ph.symmetry.name == "octant":  # planes 50-90 repeat 40-0: count each value once
            grid = replace(grid, c=grid.c[:10], candela=grid.candela[:10],
                           sigma=grid.sigma[:10])
        z = z_scores(grid, truth[None, :], scene.total_flux / photons, averaged)
        # no value beyond the normal's 1-in-2000 tail for this many values (4 sigma for
        # a rotational grid's 73)
        limit = max(4.0, float(stats.norm.isf(2.5e-4 / len(z))))
        assert np.abs(z).max() < limit, (name, photons, np.abs(z).max(), limit)
        pooled.append(z)
    z = np.concatenate(pooled)
    assert len(z) > 300
    # honest errors: unit variance (sd of the sample variance of n z-scores: sqrt(2 / n))
    assert abs(np.var(z) - 1.0) < 4.0 * math.sqrt(2.0 / len(z)), np.var(z)
    assert abs(np.mean(z)) < 4.0 / math.sqrt(len(z))


def test_nothing_above_the_horizon_of_a_one_sided_disc(measured):
    for name, photons, scene, result, ph, truth, _ in measured:
        if name != "lambertian_disc":
            continue
        above = ph.grid.gamma > 90.0 + 1.25
        assert np.all(ph.grid.candela[:, above] == 0.0)
        assert ph.figures.upward_flux_fraction == 0.0
        # the 90 deg value's window straddles the horizon: it reads the kink as the fit does
        j = int(np.flatnonzero(ph.grid.gamma == 90.0)[0])
        assert abs(ph.grid.candela[0, j] - truth[j]) < 4.0 * ph.grid.sigma[0, j]


def test_flux_peak_and_angles_within_their_stated_errors(measured):
    for name, photons, scene, result, ph, truth, expectation in measured:
        f = ph.figures
        want = expected_figures(expectation)
        assert abs(f.luminous_flux - want["escaped_flux"]) <= 4.0 * f.luminous_flux_error + \
            1e-9 * want["escaped_flux"], (name, photons)
        assert abs(f.peak_intensity - truth.max()) < 4.0 * f.peak_intensity_error, \
            (name, photons, f.peak_intensity, truth.max(), f.peak_intensity_error)
        if name == "mirror_cup":  # the 50% level falls just past a step (a 2nd reflection)
            g = np.linspace(0.0, 90.0, 900_001)
            prof = expected_intensity(expectation, frame.directions(np.zeros_like(g), g, "Z"))
            beam = 2.0 * g[np.flatnonzero(prof >= 0.5 * prof.max())[-1]]
            assert abs(f.beam_angle_c0_c180 - beam) < 4.0 * f.beam_angle_c0_c180_error + 0.25, \
                (photons, f.beam_angle_c0_c180, f.beam_angle_c0_c180_error, beam)
        if name == "lambertian_disc":
            for v, e in ((f.beam_angle_c0_c180, f.beam_angle_c0_c180_error),
                         (f.beam_angle_c90_c270, f.beam_angle_c90_c270_error)):
                assert abs(v - 120.0) < 4.0 * e, (photons, v, e)
            field = 2.0 * math.degrees(math.acos(0.1))
            assert abs(f.field_angle_c0_c180 - field) < 4.0 * f.field_angle_c0_c180_error
            # CIE flux code: sin^2 of the zone edges (cones of pi/2, pi, 3 pi/2 sr)
            for v, e, exact in zip(f.cie_flux_code_values, f.cie_flux_code_errors,
                                   (43.75, 75.0, 93.75)):
                assert abs(v - exact) < 4.0 * e, (v, e, exact)


def test_the_written_files_hold_the_measured_values(tmp_path):
    """IES and LDT read back: the grid's values, within the files' rounding, agree with the
    closed form (as the point values read it) within 4 stated standard errors (taken from
    the sidecar JSON)."""
    import json
    import shutil

    stage = tmp_path / "lambertian_disc.usda"
    shutil.copy(REFERENCE / "lambertian_disc.usda", stage)
    scene = read_stage(stage)
    result = run(scene, TraceSettings(photons=1_000_000, seed=3, resolution=32))
    record = write_outputs(result, None, pictures=False)
    data = json.loads((tmp_path / "lambertian_disc.photometry.json").read_text())
    sigma = np.array(data["sigma"])
    assert record["photometry_data"] == str(tmp_path / "lambertian_disc.photometry.json")
    ies = read_ies(record["ies"]).grid()
    grid = photometry_of(scene, result.accumulator).grid
    truth = point_truth(read_expectation(stage), grid)
    assert np.allclose(ies.candela, data["candela"], rtol=1e-5, atol=1e-3)
    live = sigma[0] > 0
    assert np.abs((ies.candela[0] - truth) / np.where(live, sigma[0], 1.0))[live].max() < 4.0
    ldt = read_ldt(record["ldt"]).grid
    assert np.allclose(ldt.candela[0], ies.candela[0], rtol=1e-3, atol=1e-2)
    assert record["peak_intensity"] == data["figures"]["peak_intensity"]
    assert record["photometry_error"] == pytest.approx(data["figures"]["photometry_error"])
