"""The filtered map never makes things worse: on the reference stages with a closed form,
at every iteration, its true relative RMS error is at most the raw map's (within noise)."""
from __future__ import annotations

import numpy as np
import pytest

from lumitrace.film.convergence import relative_rms
from lumitrace.film.cubemap import texel_solid_angles
from lumitrace.film.texel_quadrature import texel_integrals
from lumitrace.report.references import expected_intensity, read_expectation
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage
from helpers.paths import REFERENCE


@pytest.mark.parametrize("name", ["lambertian_disc", "mirror_cup", "isotropic", "fresnel_slab"])
@pytest.mark.parametrize("res", [12, 32])
def test_the_filtered_map_is_never_worse_than_the_raw_one(name, res):
    stage = REFERENCE / f"{name}.usda"
    expectation = read_expectation(stage)
    omega = texel_solid_angles(res)
    truth = texel_integrals(lambda d: expected_intensity(expectation, d), res) / omega
    seen = []
    run(read_stage(stage), TraceSettings(photons=1_500_000, seed=4, resolution=res),
        progress=lambda p: seen.append((relative_rms(p.estimate.filtered, truth, omega),
                                        relative_rms(p.estimate.raw, truth, omega))))
    assert len(seen) >= 5
    for i, (filtered, raw) in enumerate(seen):
        # within noise: the raw error itself scatters by about 1 / sqrt(2 texels) of itself
        assert filtered <= raw * (1.0 + 3.0 / np.sqrt(2 * 6 * res * res)), (i, filtered, raw)
