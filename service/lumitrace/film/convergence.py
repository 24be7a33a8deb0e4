"""How far a map is from the truth: measured against a reference, estimated without one.

The error of a map is its relative RMS error over the sphere,
``sqrt(sum(Omega (I - I_true)^2) / sum(Omega I_true^2))``: the solid-angle weighted L2
distance, relative to the distribution's own size, so dark texels do not dominate it.

Without a reference it is estimated from the photons themselves. Raw maps: every texel's
count is binomial, so its variance is known. Filtered maps: the photons are split into two
pseudo-random halves (by the photon hash), each half is filtered on its own (with the weights
its own photons give, at half the threshold), and their difference measures the filtered
map's variance; its bias is what remains of the distance between one half's filtered map
and the other half's raw map (independent of it) once both noises are taken out.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from .accumulate import Accumulator
from .cubemap import texel_solid_angles
from .pullpush import pull_push


def norm2(image: np.ndarray, omega: np.ndarray) -> float:
    """Solid-angle weighted squared L2 norm of a map (cd^2 sr)."""
    return float((omega * image * image).sum())


def relative_rms(image: np.ndarray, reference: np.ndarray, omega: np.ndarray | None = None) -> float:
    """Relative RMS error of ``image`` against ``reference`` (both cd, (6R, R))."""
    omega = texel_solid_angles(image.shape[1]) if omega is None else omega
    ref = norm2(reference, omega)
    return float(np.sqrt(norm2(image - reference, omega) / ref)) if ref > 0 else float("inf")


def _raw_noise2(acc: Accumulator, omega: np.ndarray) -> float:
    """Expected squared norm of the raw map's noise: sum of Var(I) Omega = Var(F) / Omega."""
    return float((acc.flux_variance() / omega).sum())


def raw_relative_error(acc: Accumulator) -> float:
    """Estimated relative RMS error of the raw map, from binomial texel variances."""
    if acc.photons < 2 or not acc.spread_known:
        return math.inf  # one photon (of the map, or of a light) says nothing of its spread
    omega = texel_solid_angles(acc.resolution)
    raw = acc.intensity()
    noise2 = _raw_noise2(acc, omega)
    signal2 = norm2(raw, omega) - noise2  # E|I|^2 = |I_true|^2 + noise
    if signal2 <= 0:
        return float("inf")
    return float(np.sqrt(noise2 / signal2))


@dataclass(frozen=True)
class MapEstimate:
    """The raw and filtered maps of an accumulator and their estimated errors."""

    raw: np.ndarray
    filtered: np.ndarray
    threshold: float
    raw_error: float
    filtered_error: float
    filtered_variance_error: float
    texel_error: np.ndarray
    #: the filter was estimated to make the map worse, so ``filtered`` is the raw map
    stepped_back: bool = False
    #: ``filtered_error`` with its bias term raised by that term's own standard deviation
    filtered_error_bound: float | None = None

    @property
    def error(self) -> float:
        """The estimated error of the map written as ``Y`` (filtered, or raw at threshold 0)."""
        return self.filtered_error if self.threshold > 0 else self.raw_error

    @property
    def error_bound(self) -> float:
        """An upper estimate of :attr:`error`, what convergence is judged on: the filtered
        map's bias is estimated against a raw map far noisier than it, so the estimate is
        uncertain by that noise's spread; the raw map's binomial estimate is not."""
        if self.threshold > 0 and self.filtered_error_bound is not None:
            return self.filtered_error_bound
        return self.error

    def scaled(self, k: float) -> "MapEstimate":
        """The estimate of the same counts with every light's flux times ``k``: the maps
        scale, their relative errors stay."""
        return replace(self, raw=self.raw * k, filtered=self.filtered * k)

    def meets(self, target: float) -> bool:
        """Whether the map is converged at ``target`` (relative): its error bound is
        within it."""
        return self.error_bound <= target


def _raw_estimate(acc: Accumulator, raw: np.ndarray, flux: np.ndarray, threshold: float,
                  raw_err: float, stepped_back: bool = False) -> MapEstimate:
    """The estimate that writes the raw map as ``Y``, with its binomial texel errors."""
    texel = np.sqrt(acc.flux_variance()) / np.maximum(flux, 1e-300)
    return MapEstimate(raw, raw, threshold, raw_err, raw_err, raw_err,
                       np.where(flux > 0, texel, np.inf), stepped_back)


def estimate(acc: Accumulator, threshold: float,
             checkpoint: Callable[[], None] = lambda: None) -> MapEstimate:
    """Raw and pull-push filtered maps (cd) with their estimated relative RMS errors and the
    filtered map's per-texel relative standard error. ``checkpoint`` runs before each of
    the filter's passes (it may raise to abandon an estimate nobody will look at)."""
    omega = texel_solid_angles(acc.resolution)
    flux, counts = acc.texel_flux(), acc.counts()
    raw = flux / omega
    noise_raw2 = _raw_noise2(acc, omega)
    raw_err = raw_relative_error(acc)
    if threshold <= 0 or not math.isfinite(raw_err):  # no spread known: no filter judged
        return _raw_estimate(acc, raw, flux, threshold, raw_err)
    checkpoint()
    filtered = pull_push(flux, counts, threshold, omega)
    # each half filtered on its own, with the weights its own photons give at half the
    # threshold (so that it leans on its neighbours as far as the whole map does): the filter
    # adapts to its photons (a texel that departs from its neighbours is trusted), and that
    # choice is part of its noise. Halves filtered with the whole map's weights miss it:
    # on the demo at 100k photons they put the map's error at 3.1% where it was 5.2% (this
    # way 6.0%; mean of 6 seeds)
    half_flux = [acc.texel_flux(h) for h in (0, 1)]
    halves = []
    for h in (0, 1):
        checkpoint()
        halves.append(pull_push(half_flux[h], acc.counts(h), threshold / 2.0, omega))
    raw_halves = [f / omega for f in half_flux]
    diff = halves[0] - halves[1]
    # Var(f_a - f_b) = 2 Var(f_half); the whole map, from twice the photons, half of that
    var_f2 = norm2(diff, omega) / 4.0
    # bias: a half's filtered map against the other half's raw map, which is independent
    # of it: E|f_a - r_b|^2 = |bias_half|^2 + Var(f_half) + Var(r_half), halves' variances
    # twice the whole's
    cross = 0.5 * sum(norm2(halves[i] - raw_halves[1 - i], omega) for i in (0, 1))
    bias2 = max(0.0, cross - 2.0 * noise_raw2 - 2.0 * var_f2)
    total2 = var_f2 + bias2
    # the raw halves' noise, subtracted above by its expectation, varies from run to run by
    # sqrt(sum (Omega Var(r_half))^2) (Gaussian texels; the two cross terms averaged): near
    # 2% as large as the bias itself, so the bound adds it in full. A bias estimated below
    # zero is not resolved, and is bounded by that spread alone
    spread2 = float(np.sqrt((np.square(2.0 * acc.flux_variance() / omega)).sum()))
    signal2 = norm2(filtered, omega) - var_f2
    # no signal above the noise (no light escaped): the relative error is undefined
    rel = (lambda x2: float(np.sqrt(x2 / signal2))) if signal2 > 0 else (lambda x2: math.inf)
    # the bias estimate is a difference of sums of squares over the texels, uncertain by
    # about sqrt(2 / texels) of the raw noise: the filter must be better by that much
    margin = math.sqrt(2.0 / flux.size)
    if signal2 > 0 and rel(total2) >= raw_err * (1.0 - margin):
        # the filter's estimated bias costs more than the noise it takes out: step back to
        # the raw map (a preview must never be worse than the counts it comes from)
        return _raw_estimate(acc, raw, flux, threshold, raw_err, stepped_back=True)
    # per texel: the split-half variance, smoothed by the same filter
    checkpoint()
    local_var = pull_push(diff * diff / 4.0 * omega, counts, threshold, omega,
                          sharpen=False)
    texel = np.sqrt(np.maximum(local_var, 0.0)) / np.maximum(filtered, 1e-300)
    return MapEstimate(raw, filtered, threshold, raw_err, rel(total2), rel(var_f2),
                       np.where(filtered > 0, texel, np.inf),
                       filtered_error_bound=rel(total2 + spread2))


def colour_maps(acc: Accumulator, est: MapEstimate) -> dict[str, np.ndarray]:
    """The X and Z maps (cd-like, (6R, R)) beside ``est``'s Y: raw, and filtered with the
    weights that filtered Y (the raw ones where Y is written raw), so that each filtered
    texel's colour is a weighted mean of raw colours near it. Empty for a scene without
    colour."""
    if acc.colour == "none":
        return {}
    omega = texel_solid_angles(acc.resolution)
    xyz = acc.tristimulus_flux()
    raw = {"raw.X": xyz[0] / omega, "raw.Z": xyz[2] / omega}
    if est.threshold <= 0 or est.stepped_back:
        return {"X": raw["raw.X"], "Z": raw["raw.Z"], **raw}
    _, xz = pull_push(xyz[1], acc.counts(), est.threshold, omega, extra=xyz[[0, 2]])
    return {"X": xz[0], "Z": xz[1], **raw}
