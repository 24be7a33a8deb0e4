"""A flux-only edit's photometry (every light's flux times one factor, the counts as they
were) is the last one scaled, and equals the photometry measured afresh from the rescaled
counts: intensities, fluxes and their errors by the factor, every ratio and angle as it
was."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lumitrace.photometry import distribution
from lumitrace.photometry.distribution import _common_factor, photometry_of
from lumitrace.run.session import run
from lumitrace.run.settings import TraceSettings
from lumitrace.stage.reader import read_stage
from helpers.paths import ROOT


def test_a_flux_edit_scales_the_last_photometry_as_a_fresh_one_reads():
    scene = read_stage(ROOT / "stages" / "downlight.usda")
    acc = run(scene, TraceSettings(photons=60_000, resolution=16, seed=4)).accumulator
    photometry_of(scene, acc)
    acc.rescale(0, acc.emitters[0].flux * 1.37)
    scaled = photometry_of(scene, acc)
    distribution._LAST.clear()
    fresh = photometry_of(scene, acc)
    assert scaled is not fresh
    np.testing.assert_allclose(scaled.grid.candela, fresh.grid.candela, rtol=1e-12, atol=0)
    np.testing.assert_allclose(scaled.grid.sigma, fresh.grid.sigma, rtol=1e-12, atol=0)
    a, b = scaled.figures.as_dict(), fresh.figures.as_dict()
    assert a.keys() == b.keys()
    for name, value in b.items():
        if isinstance(value, float) and math.isfinite(value):
            assert a[name] == pytest.approx(value, rel=1e-9, abs=1e-12), name
        elif isinstance(value, tuple) and value and isinstance(value[0], float):
            assert a[name] == pytest.approx(value, rel=1e-9, abs=1e-12), name
        else:
            assert a[name] == value, name
    assert fresh.figures.peak_intensity > 0 and fresh.figures.beam_angle_c0_c180 is not None


def test_only_one_factor_for_every_light_is_a_rescale():
    assert _common_factor([100.0, 300.0], [150.0, 450.0]) == pytest.approx(1.5)
    assert _common_factor([100.0, 300.0], [150.0, 300.0]) is None  # one light changed
    assert _common_factor([0.0], [10.0]) is None and _common_factor([1.0], [1.0, 2.0]) is None
