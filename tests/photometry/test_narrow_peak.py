"""The peak of a beam a few degrees wide along the axis (the paraboloid's, 1.7 deg): fitted
within half its half width, not across the whole beam, it is no lower than the files' own
nadir value (a mean over a cap around the top, which the top cannot fall below) and agrees
with the innermost goniometer rings extrapolated to the axis."""
from __future__ import annotations

import numpy as np

from lumitrace.film.goniometer import cell_solid_angles
from lumitrace.photometry.distribution import photometry_of
from lumitrace.photometry.measured import emitter_rings
from lumitrace.photometry.peak import fit_radius
from helpers.reference import trace


def test_a_fit_near_a_pole_reaches_two_cells_not_a_fixed_degree_and_a_half():
    assert fit_radius(1.0, 0.1) == 0.5  # two gamma cells
    assert fit_radius(1.0, 90.0) == 1.5  # a C cell is 1.25 deg of arc here
    assert fit_radius(8.0, 0.1) == 4.0 and fit_radius(None, 0.1) == 10.0


def test_a_narrow_beams_peak_is_its_top():
    scene, result, _ = trace("paraboloid", 2_000_000, res=8)
    acc = result.accumulator
    ph = photometry_of(scene, acc)
    f = ph.figures
    nadir, nadir_err = float(ph.grid.candela[0, 0]), float(ph.grid.sigma[0, 0])
    assert f.peak_gamma < 0.5
    assert f.peak_intensity > nadir - 3.0 * np.hypot(f.peak_intensity_error, nadir_err)
    # the two innermost 0.25 deg rings, linear in the square of gamma, at gamma 0
    rings = sum(w * ring for w, _, ring in emitter_rings(acc))
    omega = cell_solid_angles().sum(axis=0)
    i0, i1 = rings[0] / omega[0], rings[1] / omega[1]
    r0, r1 = 0.25 ** 2 / 2, (0.25 ** 2 + 0.5 ** 2) / 2  # mean gamma^2 (deg^2) of each ring
    axis = i0 - (i1 - i0) / (r1 - r0) * r0
    assert abs(f.peak_intensity / axis - 1.0) < 0.03, (f.peak_intensity, axis)
    # the beam read against that top: its half width is where the rings fall to half of it
    assert 1.6 < f.beam_angle_c0_c180 < 1.9
