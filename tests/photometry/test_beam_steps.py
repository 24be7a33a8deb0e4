"""A beam angle read where the profile steps at its level: the crossing is at the step, not
half a cell outward as linear interpolation between cells' means puts it, and its bias falls
with the noise (a mirror's extra reflection ending at 56.36 deg, as the mirror cup's)."""
from __future__ import annotations

import numpy as np

from lumitrace.photometry.quantities import spread_angles

H = 0.5  # deg between samples, as the profiles beam angles are read from
ANG = np.arange(-180.0, 180.0 + 1e-9, H)
STEP = 56.357  # deg from nadir
TOP, BOTTOM, SLOPE = 0.5285, 0.4994, -0.0134  # relative intensity at the step, per deg


def _mean_over_cells(step: float = STEP, top: float = TOP, bottom: float = BOTTOM
                     ) -> np.ndarray:
    """Cells' means (0.5 deg wide, centred on ANG) of a profile falling linearly on each
    side of a step down at +-``step``: exact integrals of the piecewise-linear profile."""
    def integral(x):  # of the profile from 0 to x >= 0, each side a line through the step
        inner = top * np.minimum(x, step) + 0.5 * SLOPE * (np.minimum(x, step) - step) ** 2 \
            - 0.5 * SLOPE * step ** 2
        beyond = np.maximum(x - step, 0.0)
        return inner + bottom * beyond + 0.5 * SLOPE * beyond ** 2

    a = np.abs(ANG)
    lo, hi = a - 0.5 * H, a + 0.5 * H
    return (integral(hi) - integral(np.maximum(lo, 0.0)) + integral(np.maximum(-lo, 0.0))) / H


def test_a_step_at_the_level_is_where_the_beam_ends():
    prof = _mean_over_cells()
    sigma = np.full(len(ANG), 1e-4)
    for level in (0.5, 0.51, 0.525):  # anywhere within the step
        got = spread_angles(ANG, prof[None], np.array([level]), sigma)[0]
        assert abs(got - 2.0 * STEP) < 1e-6, (level, got)
        linear = spread_angles(ANG, prof[None], np.array([level]))[0]
        assert abs(linear - 2.0 * STEP) > 0.05  # interpolated across the step: off
    # below the step's foot the profile crosses on the line beyond it
    level = 0.49
    got = spread_angles(ANG, prof[None], np.array([level]), sigma)[0]
    assert abs(got - 2.0 * (STEP + (level - BOTTOM) / SLOPE)) < 1e-6


def test_a_smooth_profile_reads_as_before():
    """No step: the lines either side of the crossing meet, and the crossing is interpolated
    between the two samples around it, as without the step test."""
    prof = 318.3 * np.cos(np.radians(np.clip(ANG, -90, 90)))
    sigma = 0.3 * np.ones(len(ANG))
    levels = np.array([0.5, 0.1]) * 318.3
    np.testing.assert_array_equal(spread_angles(ANG, np.stack([prof, prof]), levels, sigma),
                                  spread_angles(ANG, np.stack([prof, prof]), levels))


def test_the_bias_at_a_steps_foot_falls_with_the_noise():
    """The level 0.1% of the peak above the step's foot, as the mirror cup's: noise that lifts
    the foot above the level moves the crossing out along the line beyond, so no reading is
    unbiased there, but the step model's bias falls as the noise does (it is below its
    spread), where interpolation across the step keeps its offset."""
    prof = _mean_over_cells()
    rng = np.random.default_rng(3)
    bias, spread, linear = [], [], []
    for noise in (0.004, 0.001):  # relative standard error of a sample (2M and 32M photons)
        draws = prof + noise * rng.standard_normal((2000, len(ANG)))
        draws[:, ANG < 0] = draws[:, ANG > 0][:, ::-1]  # both sides are the same values
        levels = 0.5 + 0.5 * 0.0066 * (noise / 0.004) * rng.standard_normal(2000)
        got = spread_angles(ANG, draws, levels, np.full(len(ANG), noise))
        bias.append(got.mean() - 2.0 * STEP)
        spread.append(got.std())
        linear.append(spread_angles(ANG, draws, levels).mean() - 2.0 * STEP)
    assert bias[0] < spread[0] and bias[1] < spread[1]
    assert bias[1] < 0.4 * bias[0]
    assert min(linear) > 0.3  # a quarter degree per side, whatever the noise


def test_the_outermost_crossings_are_where_the_beam_angle_ends():
    """The crossings a datasheet lists (``beam_crossings_*``) end where the beam angle does,
    at the step on both sides."""
    from lumitrace.photometry.quantities import _step_read, crossings, outermost_crossings

    prof = _mean_over_cells()
    sigma = np.full(len(ANG), 1e-4)
    level = np.array([0.5])
    left, right = outermost_crossings(ANG, prof[None], level, sigma)
    assert abs(left[0] + STEP) < 1e-6 and abs(right[0] - STEP) < 1e-6
    listed = _step_read(crossings(ANG, prof, 0.5), (left, right))
    assert listed[-1] - listed[0] == spread_angles(ANG, prof[None], level, sigma)[0]
    assert len(listed) == len(crossings(ANG, prof, 0.5))
