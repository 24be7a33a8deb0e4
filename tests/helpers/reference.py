"""Tracing the reference stages and comparing texel counts with their closed forms."""
from __future__ import annotations

import numpy as np
from scipy import stats

from lumitrace.film.texel_quadrature import texel_integrals
from lumitrace.report.references import expected_intensity, read_expectation
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage

from .paths import REFERENCE as STAGES


def trace(name: str, photons: int, res: int = 16, seed: int = 1, threads: int = 2):
    stage = STAGES / f"{name}.usda"
    scene = read_stage(stage)
    result = run(scene, TraceSettings(photons=photons, resolution=res, seed=seed, threads=threads))
    return scene, result, read_expectation(stage)


def chi2_pvalue(observed: np.ndarray, expected: np.ndarray, min_expected: float = 20.0) -> float:
    """Pearson chi-square p-value of texel counts, pooling texels of small expectation.

    Photons outside every expected texel (expected 0, observed > 0) give p = 0.
    """
    o = observed.ravel().astype(float)
    e = expected.ravel()
    if (o[e <= 0] > 0).any():
        return 0.0
    big = e >= min_expected
    o_b, e_b = list(o[big]), list(e[big])
    if e[~big & (e > 0)].sum() > 0:
        o_b.append(o[~big].sum())
        e_b.append(e[~big].sum())
    o_b, e_b = np.array(o_b), np.array(e_b)
    stat = ((o_b - e_b) ** 2 / e_b).sum()
    return float(stats.chi2.sf(stat, len(o_b) - 1))


def expected_counts(expectation: dict, res: int, photons: int) -> np.ndarray:
    """Photons expected in every texel: N * integral(I dOmega) / flux."""
    integ = texel_integrals(lambda d: expected_intensity(expectation, d), res)
    return photons * integ / float(expectation["flux"])
