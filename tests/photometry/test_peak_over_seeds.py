"""The peak intensity over seeds, against the closed form: a Lambertian disc's flat top at
the fewest photons a files' target allows (98,304), where a top located in the noise sits
degrees off the axis and the value measured there is low (by 1%, 3 of its standard errors
over 200 seeds, before the pole a rotational symmetry fixes was measured as the top)."""
from __future__ import annotations

import numpy as np

from lumitrace.photometry.distribution import photometry_of
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage
from helpers.paths import REFERENCE

SEEDS = 200
PHOTONS = 98_304
PEAK = 1000.0 / np.pi  # cd: the 1000 lm Lambertian disc, I = (flux / pi) cos(gamma)


def test_a_lambertian_discs_peak_is_unbiased_and_its_error_honest():
    scene = read_stage(REFERENCE / "lambertian_disc.usda")
    value, error, gamma = [], [], []
    for seed in range(SEEDS):
        acc = run(scene, TraceSettings(photons=PHOTONS, seed=seed, threads=1)).accumulator
        f = photometry_of(scene, acc).figures
        value.append(f.peak_intensity)
        error.append(f.peak_intensity_error)
        gamma.append(f.peak_gamma)
    value, error = np.array(value), np.array(error)
    assert np.mean(np.array(gamma) == 0.0) > 0.8  # the pole, where the symmetry puts it
    mean_error = value.std(ddof=1) / np.sqrt(SEEDS)
    assert abs(value.mean() - PEAK) < 2.5 * mean_error, (value.mean() / PEAK - 1, mean_error)
    assert 0.8 < value.std(ddof=1) / error.mean() < 1.25
    z2 = np.mean(((value - PEAK) / error) ** 2)
    assert 0.7 < z2 < 1.4, z2
