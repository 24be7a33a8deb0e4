"""Pull-push filtering of a noisy cube-map intensity map.

A photon map at low counts is mostly empty or noisy texels. Pull: photon counts and flux
are summed into coarser and coarser cube maps, down to the whole sphere. Push: from the
coarsest level back to the finest, each texel keeps its own intensity in proportion to its
photon count and takes the rest from the coarser level, interpolated bilinearly at its
direction: ``I = w I_own + (1 - w) I_coarse`` with ``w = min(1, c / threshold)``, where the
confidence ``c`` is the larger of the texel's photon count and the count the coarser level
predicts for it: a texel left empty where many photons were expected is dark, not unknown.
Where the texels of a region differ from the coarser level by more than their photon noise
explains (an edge, a narrow beam), the coarser level is biased there and the texels get the
weight that minimises the expected squared error, ``bias^2 / (bias^2 + noise^2)``, so edges
and peaks stay sharp while flat regions are smoothed.
Intensities (flux per solid angle), not fluxes, are blended, because texel solid angles
differ across a face. The pixel positions of the ImfEnvmap layout reach the cube's edges,
so bilinear lookups never cross a face and, with shared edge texels welded, the result is
seamless. The total flux is restored exactly at the end, a threshold of 0 returns the raw
map, and as counts grow every weight reaches 1: the filtered map converges to the raw one.
Cost is linear in the number of texels.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .cubemap import (bilinear_taps, sample_map, texel_directions, texel_index,
                      texel_solid_angles, weld_seams)

FOUR_PI = 4.0 * np.pi


@dataclass(frozen=True)
class _Level:
    """One pyramid level: its face size and, for every texel of the finer level below it,
    the index of the coarse texel its direction falls in."""

    res: int
    parent: np.ndarray
    directions: np.ndarray
    taps: tuple  # bilinear taps of ``directions`` in this level's map (cube-map lookups)


@functools.lru_cache(maxsize=8)
def _pyramid(res: int) -> tuple[_Level, ...]:
    """Face sizes res, ~res/2, ..., 2 and the fine-to-coarse texel maps between them."""
    levels = []
    fine = res
    while fine > 2:
        coarse = max(2, (fine + 1) // 2)
        d = texel_directions(fine).reshape(-1, 3)
        levels.append(_Level(res=coarse, parent=texel_index(d, coarse), directions=d,
                             taps=bilinear_taps(d, coarse)))
        fine = coarse
    d = texel_directions(fine).reshape(-1, 3)
    levels.append(_Level(res=fine, parent=np.zeros(6 * fine * fine, np.int64),
                         directions=d, taps=bilinear_taps(d, fine)))
    return tuple(levels)


def pull_push(flux: np.ndarray, counts: np.ndarray, threshold: float,
              solid_angles: np.ndarray | None = None, adaptive: bool = True,
              extra: np.ndarray | None = None):
    """Filtered intensity (cd), (6R, R), from texel fluxes (lm) and photon counts.

    ``threshold`` is the photon count from which a texel trusts its own estimate fully.
    ``extra`` (k, 6R, R), other quantities per texel (the X and Z of the same photons), are
    filtered with the weights the intensity's counts and noise give, so that a filtered
    colour is a weighted mean of raw colours nearby (no fringes at a beam's edge); then
    (intensity, extra filtered) is returned.
    """
    shape = flux.shape
    res = shape[1]
    omega = texel_solid_angles(res) if solid_angles is None else solid_angles
    channels = np.concatenate([flux[None], extra]) if extra is not None else flux[None]
    totals = channels.reshape(len(channels), -1).sum(axis=1)
    total = float(totals[0])
    if threshold <= 0 or total <= 0:
        raw = channels / omega
        return raw[0] if extra is None else (raw[0], raw[1:])

    # pull: flux, counts and solid angle of every level, finest first
    f = [channels.reshape(len(channels), -1)]
    n, w = [counts.ravel().astype(np.float64)], [omega.ravel()]
    levels = _pyramid(res)
    for lv in levels[:-1]:
        size = 6 * lv.res * lv.res
        f.append(np.stack([np.bincount(lv.parent, weights=c, minlength=size) for c in f[-1]]))
        n.append(np.bincount(lv.parent, weights=n[-1], minlength=size))
        w.append(np.bincount(lv.parent, weights=w[-1], minlength=size))

    photons_per_lumen = float(n[0].sum()) / total

    # push: the whole sphere, then every level from coarse to fine
    coarse = np.repeat((totals / FOUR_PI)[:, None], 6 * levels[-1].res ** 2, axis=1)
    coarse_res = levels[-1].res
    for depth in range(len(levels) - 1, -1, -1):
        lv_res = res if depth == 0 else levels[depth - 1].res
        dirs = levels[depth].directions
        own = np.divide(f[depth], w[depth], out=np.zeros_like(f[depth]), where=w[depth] > 0)
        below = np.stack([sample_map(c.reshape(6 * coarse_res, coarse_res), dirs,
                                     levels[depth].taps) for c in coarse])
        # confidence in the texel's own estimate: the photons it holds, or the photons the
        # coarser level predicts for it; an empty texel where many were expected is dark
        expected = below[0] * w[depth] * photons_per_lumen
        weight = np.minimum(1.0, np.maximum(n[depth], expected) / threshold)
        if adaptive and depth < len(levels) - 1:
            # where the coarse level disagrees with the texels by more than their noise
            # explains, it is biased there (an edge, a peak): trust the texels more
            var_own = below[0] * below[0] / np.maximum(expected, 1.0)
            lv = levels[depth]
            size = 6 * lv.res * lv.res
            group = lambda x: np.bincount(lv.parent, weights=x, minlength=size)  # noqa: E731
            area = group(w[depth])
            own_g = np.divide(group(f[depth][0]), area, out=np.zeros(size), where=area > 0)
            pred_g = np.divide(group(below[0] * w[depth]), area, out=np.zeros(size),
                               where=area > 0)
            lam_g = group(expected)
            var_g = pred_g * pred_g / np.maximum(lam_g, 1.0)
            dev2 = (own_g - pred_g) ** 2
            # a group of texels whose photon count departs from the coarse prediction by
            # more than Poisson noise allows (3 sigma, plus 3 photons for the skewed tails of
            # small counts) shows where the prediction is biased
            significant = np.abs(group(n[depth]) - lam_g) > 3.0 * np.sqrt(lam_g) + 3.0
            bias2_g = np.where(significant, np.maximum(dev2 - var_g, 0.0), 0.0)
            local = weld_seams(bias2_g.reshape(6 * lv.res, lv.res), area.reshape(6 * lv.res, lv.res))
            bias2 = np.maximum(sample_map(local, dirs, lv.taps), 0.0)
            weight = np.maximum(weight, bias2 / np.maximum(bias2 + var_own, 1e-300))
        value = weight * own + (1.0 - weight) * below
        area = w[depth].reshape(6 * lv_res, lv_res)
        coarse = np.stack([weld_seams(v.reshape(6 * lv_res, lv_res), area).ravel()
                           for v in value])
        coarse_res = lv_res

    # the intensity's total flux restored exactly; the other quantities scaled alike, so
    # that a colour stays a weighted mean of raw ones
    out = coarse.reshape(len(channels), *shape)
    kept = float((out[0] * omega).sum())
    out = out * (total / kept) if kept > 0 else out
    return out[0] if extra is None else (out[0], out[1:])
