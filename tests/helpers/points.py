"""What the files' point values read from a closed form: the closed form's mean over each
goniometer gamma bin (integrated finely, solid-angle weighted), through the same fixed
weights the point values are (:func:`lumitrace.photometry.measured.point_operators`). A
measured value minus this is noise alone, so z-scores against it test the stated errors;
where the closed form is smooth it is the closed form's value at the listed angle."""
from __future__ import annotations

import numpy as np

from lumitrace.film.goniometer import GAMMA_EDGES
from lumitrace.photometry.measured import point_operators


def bin_means(profile, samples: int = 16) -> np.ndarray:
    """A rotationally symmetric profile's (``profile(gamma_rad)`` -> cd) solid-angle mean
    over each goniometer gamma bin, (N_GAMMA,)."""
    lo, hi = np.radians(GAMMA_EDGES[:-1]), np.radians(GAMMA_EDGES[1:])
    t = (np.arange(samples) + 0.5) / samples
    g = lo[:, None] + (hi - lo)[:, None] * t[None, :]
    w = np.sin(g)
    return (profile(g) * w).sum(axis=1) / w.sum(axis=1)


def read_points(profile, gammas: np.ndarray, pole_caps: tuple[float, float]) -> np.ndarray:
    """The point values the files' estimator reads from ``profile`` at ``gammas``, the poles
    over the caps of half-angles ``pole_caps`` (deg, as the grid chose them): the fit, or
    the mean of the bins beside the angle where the fit dips below zero."""
    first, weights, poles, angles = point_operators(tuple(map(float, gammas)))
    means = bin_means(profile)
    take = first[:, None] + np.arange(weights.shape[2])[None, :]
    fit, mean = ((means[take] * w).sum(axis=1) for w in weights)
    out = np.where(fit < 0, mean, fit)
    for p, half in enumerate(pole_caps):
        k = int(np.argmin(np.abs(angles[p] - half)))
        fit, cap = poles[0, p, k] @ means, poles[1, p, k] @ means
        out[0 if p == 0 else -1] = cap if fit < 0 else fit
    return out
