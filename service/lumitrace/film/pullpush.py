"""Pull-push filtering of a noisy cube-map intensity map.

A photon map at low counts is mostly empty or noisy texels. Pull: photon counts and flux
are summed into coarser and coarser cube maps, down to the whole sphere. Push: from the
coarsest level back to the finest, each texel keeps its own intensity in proportion to its
photon count and takes the rest from the coarser level, interpolated bilinearly at its
direction: ``I = w I_own + (1 - w) I_coarse`` with ``w = min(1, c / threshold)``, where the
confidence ``c`` is the larger of the texel's photon count and the count the coarser level
predicts for it: a texel left empty where many photons were expected is dark, not unknown.
Where the texels of a region differ from the coarser level by more than their photon noise
explains (an edge, a narrow beam, a cut-off angle), the coarser level is biased there and
the texels get the weight that minimises the expected squared error,
``bias^2 / (bias^2 + noise^2)``, so edges and peaks stay sharp while flat regions are
smoothed. The test is a chi-square of the texels' counts under each coarse texel, and the
bias their mean squared departure beyond noise: an edge through the group leaves its mean
unchanged, and tested on the mean alone the white cup's cut-off at 26.6 deg was smeared
(its map needed 1.36x the photons to reach 2% on the C 15 x gamma 5 deg grid, mean of 8
seeds; the Lambertian disc 1.13x, the mirror cup 1.11x).
Sharpening: a blend of coarser levels flattens a curved lobe (a cosine falls too slowly
near its peak and too fast near its foot). The residual, raw minus filtered, holds that
bias plus noise; filtered again with the same weights and added back, it cancels the bias
to the next order (Tukey's twicing): on a Lambertian disc at 300k photons the map's error
falls by a quarter at the same threshold, and a texel can trust its neighbours for longer
(the default threshold 1e4, not 2500, which with it takes off two fifths).
Intensities (flux per solid angle), not fluxes, are blended, because texel solid angles
differ across a face. The pixel positions of the ImfEnvmap layout reach the cube's edges,
so bilinear lookups never cross a face and, with shared edge texels welded, the result is
seamless. The total flux is restored exactly at the end, a threshold of 0 returns the raw
map, and as counts grow every weight reaches 1: the residual vanishes and the filtered
map converges to the raw one.
Cost is linear in the number of texels; the push runs compiled once the tracer's kernels
are loaded (a map's estimate, four filters: 4.8 ms at face size 64 against 10.9 ms in
numpy, 111 against 185 ms at 256).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .cubemap import (_seams, bilinear_taps, sample_map, texel_directions, texel_index,
                      texel_solid_angles)
from ..table_cache import kept_table

FOUR_PI = 4.0 * np.pi


@dataclass(frozen=True)
class _Level:
    """One pyramid level: its face size and, for every texel of the finer level below it,
    the index of the coarse texel its direction falls in."""

    res: int
    parent: np.ndarray
    directions: np.ndarray
    taps: tuple  # bilinear taps of ``directions`` in this level's map (cube-map lookups)


@kept_table
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
              extra: np.ndarray | None = None, sharpen: bool = True,
              weights: list[np.ndarray] | None = None):
    """Filtered intensity (cd), (6R, R), from texel fluxes (lm) and photon counts.

    ``threshold`` is the photon count from which a texel trusts its own estimate fully.
    ``sharpen`` filters the residual (raw minus filtered) once more with the same weights
    and adds it back, which takes out the smoothing's bias on curved lobes (see the module
    docstring); a map of variances is filtered without it.
    ``extra`` (k, 6R, R), other quantities per texel (the X and Z of the same photons), are
    filtered with the weights the intensity's counts and noise give, so that a filtered
    colour is a weighted mean of raw colours nearby (no fringes at a beam's edge); then
    (intensity, extra filtered) is returned.
    ``weights``, an empty list, receives the blend weights of every level; a list filled
    so by an earlier call makes this one filter with them (the same linear filter, for
    other photons of the same map: its split halves).
    """
    shape = flux.shape
    res = shape[1]
    omega = texel_solid_angles(res) if solid_angles is None else solid_angles
    # float64 arrays of the filter's own (the compiled push takes no other types)
    channels = np.array(np.concatenate([flux[None], extra]) if extra is not None
                        else flux[None], dtype=np.float64)
    totals = channels.reshape(len(channels), -1).sum(axis=1)
    total = float(totals[0])
    if threshold <= 0 or total <= 0:
        raw = channels / omega
        return raw[0] if extra is None else (raw[0], raw[1:])

    levels = _pyramid(res)
    n = _pull(counts.ravel().astype(np.float64), levels)
    w = _pull(np.array(omega, np.float64).ravel(), levels)
    weights = [] if weights is None else weights
    out = _push(_pull(channels.reshape(len(channels), -1), levels), n, w, levels, res,
                threshold, adaptive, weights)
    if sharpen:
        # the smoothing's bias, estimated by the same filter from what it left out
        residual = flux.ravel() - out[0] * omega.ravel()
        fix = _push(_pull(residual[None], levels), n, w, levels, res, threshold, adaptive,
                    weights)
        once = out[0].copy()
        out[0] = np.maximum(once + fix[0], 0.0)
        # the other quantities follow the intensity: a colour keeps its filtered mean
        out[1:] *= np.divide(out[0], once, out=np.ones_like(once), where=once > 0)

    # the intensity's total flux restored exactly; the other quantities scaled alike, so
    # that a colour stays a weighted mean of raw ones
    out = out.reshape(len(channels), *shape)
    kept = float((out[0] * omega).sum())
    out = out * (total / kept) if kept > 0 else out
    return out[0] if extra is None else (out[0], out[1:])


def _pull(values: np.ndarray, levels: tuple[_Level, ...]) -> list[np.ndarray]:
    """``values`` (..., texels) summed into every level's texels, finest first."""
    out = [values]
    for lv in levels[:-1]:
        size = 6 * lv.res * lv.res
        v = out[-1]
        out.append(np.bincount(lv.parent, weights=v, minlength=size) if v.ndim == 1 else
                   np.stack([np.bincount(lv.parent, weights=c, minlength=size) for c in v]))
    return out


#: One level of the push as the tracer's kernels compile it
#: (:func:`lumitrace.trace.kernels.filtering.push_level`), registered by them when they load
#: (the film comes before the tracer, so it cannot import them); None: :func:`_level`, the
#: same arithmetic in numpy, the same bits (tested), several times the time.
compiled_level = None


def use_compiled_level(push_level) -> None:
    """Filter with ``push_level`` from now on (the tracer's compiled kernels call this)."""
    global compiled_level
    compiled_level = push_level


def _push(f: list[np.ndarray], n: list[np.ndarray], w: list[np.ndarray],
          levels: tuple[_Level, ...], res: int, threshold: float, adaptive: bool,
          weights: list[np.ndarray]) -> np.ndarray:
    """The finest level's blended intensities (k, texels) from the pulled fluxes ``f``,
    counts ``n`` and solid angles ``w`` of a map of face size ``res``: from the whole sphere
    down, every level's own intensity blended with the coarser level's. The blend weights
    are computed and appended to ``weights`` when it is empty, and taken from it otherwise."""
    replay = bool(weights)
    photons_per_lumen = float(n[0].sum()) / float(f[0][0].sum()) if not replay else 0.0
    coarse = np.repeat(f[-1].sum(axis=1, keepdims=True) / FOUR_PI, 6 * levels[-1].res ** 2,
                       axis=1)
    last = len(levels) - 1
    level = compiled_level or _level
    for step, depth in enumerate(range(last, -1, -1)):
        lv = levels[depth]
        canon, shared = _seams(res if depth == 0 else levels[depth - 1].res)
        canon_c, shared_c = _seams(lv.res)
        weight = weights[step] if replay else np.empty(len(w[depth]))
        coarse = level(coarse, lv.taps[0], lv.taps[1], f[depth], w[depth], n[depth],
                       lv.parent, canon, shared, canon_c, shared_c, weight, replay,
                       adaptive and depth < last, float(threshold), photons_per_lumen)
        if not replay:
            weights.append(weight)
    return coarse


def _level(coarse, idx, tw, f, w, cnt, parent, canon, shared, canon_c, shared_c, weight,
           replay, adaptive, threshold, photons_per_lumen) -> np.ndarray:
    """One level of the push in numpy: its intensities (k, n), welded, blended from its
    own (pulled fluxes ``f`` over solid angles ``w``) and the coarser level's ``coarse``
    (k, nc) at the taps ``idx``, ``tw``, with ``weight`` (n) as given where ``replay``,
    else computed into it (``parent``, ``canon_c``, ``shared_c``: the groups under each
    coarse texel and the coarse level's seams; ``canon``, ``shared``: this level's)."""
    taps = (idx, tw)
    own = np.divide(f, w, out=np.zeros_like(f), where=w > 0)
    below = np.stack([sample_map(_image(c), None, taps) for c in coarse])
    if not replay:
        weight[:] = _weight(below[0], own[0], cnt, w, parent, taps, canon_c, shared_c,
                            len(coarse[0]), threshold, photons_per_lumen, adaptive)
    value = weight * own + (1.0 - weight) * below
    return np.stack([_welded(v, w, canon, shared) for v in value])


def _image(v: np.ndarray) -> np.ndarray:
    """A level's texels (6 R^2) as its cube-map image (6R, R)."""
    res = int(round(np.sqrt(v.size / 6)))
    return v.reshape(6 * res, res)


def _welded(v: np.ndarray, area: np.ndarray, canon: np.ndarray, shared: np.ndarray
            ) -> np.ndarray:
    """:func:`~lumitrace.film.cubemap.weld_seams` of one level's texels ``v`` (area
    weights ``area``), its seams ``canon``, ``shared`` given."""
    wsum = np.bincount(canon, weights=area, minlength=v.size)
    num = np.bincount(canon, weights=v * area, minlength=v.size)
    out = v.copy()
    at = canon[shared]
    out[shared] = num[at] / wsum[at]
    return out


def _weight(below, own, n, w, parent, taps, canon_c, shared_c, size, threshold,
            photons_per_lumen, adaptive):
    """Per texel of one level, the weight of its own intensity ``own`` against the coarser
    level's ``below`` (cd): its confidence, raised where the coarser level is biased."""
    # confidence in the texel's own estimate: the photons it holds, or the photons the
    # coarser level predicts for it; an empty texel where many were expected is dark
    expected = below * w * photons_per_lumen
    weight = np.minimum(1.0, np.maximum(n, expected) / threshold)
    if not adaptive:
        return weight
    # where the coarse level disagrees with the texels by more than their noise explains,
    # it is biased there (an edge, a peak): trust the texels more. Tested and measured per
    # group of texels under one coarse texel, texel by texel: an edge through a group
    # leaves the group's mean where the coarse level predicts it, not its texels
    var_own = below * below / np.maximum(expected, 1.0)
    group = lambda x: np.bincount(parent, weights=x, minlength=size)  # noqa: E731
    area = group(w)
    excess = np.divide(group(w * ((own - below) ** 2 - var_own)), area, out=np.zeros(size),
                       where=area > 0)
    # significant: the photon counts' chi-square against the coarse prediction exceeds its
    # mean (the group's texels) by six standard deviations, plus 6 for the heavy tails of
    # small counts. A false alarm hands a group its raw noise: on an isotropic source at
    # 100k photons one such group doubles or triples the map's error, and at five sigma
    # plus 3 five seeds in eight had one (at six plus 6, one)
    m = group(np.ones_like(n))
    chi2 = group((n - expected) ** 2 / np.maximum(expected, 1.0))
    significant = chi2 > m + 6.0 * np.sqrt(2.0 * m) + 6.0
    bias_g = np.sqrt(np.where(significant, np.maximum(excess, 0.0), 0.0))
    # the bias's amplitude (cd) is what varies smoothly from group to group: it is
    # interpolated to the texels and squared after (the square interpolated would hand a
    # texel halfway to an unbiased group half the squared bias, not a quarter)
    local = _welded(bias_g, area, canon_c, shared_c)
    bias2 = np.maximum(sample_map(_image(local), None, taps), 0.0) ** 2
    return np.maximum(weight, bias2 / np.maximum(bias2 + var_own, 1e-300))
