"""The pull-push filter's push step (:mod:`lumitrace.film.pullpush`), compiled: one level's
blend of its own intensities with the coarser level's, its weights and its welded seams in
one pass over its texels, where numpy took a score of array passes (a map's estimate is
four filters, at the end of every run and in every round the live view shows).

The arithmetic is the film's numpy level (:func:`lumitrace.film.pullpush._level`), operation
for operation and sum for sum in the same order (``np.bincount`` adds in input order, a
bilinear lookup adds its taps first to last), so the filtered maps are the same to the bit
(tested); :mod:`lumitrace.trace.compiled` registers it with the film as it loads.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .jit import _JIT


@numba.njit(**_JIT)
def _group_sums(parent, x, size):
    """``np.bincount(parent, weights=x, minlength=size)``: the sums of ``x`` per group."""
    out = np.zeros(size)
    for i in range(parent.shape[0]):
        out[parent[i]] += x[i]
    return out


@numba.njit(**_JIT)
def _weld(v, area, canon, shared):
    """:func:`lumitrace.film.cubemap.weld_seams` of one channel ``v`` (texels) in place:
    texels that share a position (``canon``, ``shared``) take their area-weighted mean."""
    n = v.shape[0]
    wsum = np.zeros(n)
    num = np.zeros(n)
    for i in range(n):
        wsum[canon[i]] += area[i]
        num[canon[i]] += v[i] * area[i]
    for i in range(n):
        if shared[i]:
            v[i] = num[canon[i]] / wsum[canon[i]]


@numba.njit(**_JIT)
def _lookup(img, idx, tw, i):
    """:func:`lumitrace.film.cubemap.sample_map` of ``img`` at texel ``i``'s taps."""
    return ((tw[0, i] * img[idx[0, i]] + tw[1, i] * img[idx[1, i]])
            + tw[2, i] * img[idx[2, i]]) + tw[3, i] * img[idx[3, i]]


@numba.njit(**_JIT)
def push_level(coarse, idx, tw, f, w, cnt, parent, canon, shared, canon_c, shared_c, weight,
               replay, adaptive, threshold, photons_per_lumen):
    """One level of the push: the level's intensities (k, n), welded, from its pulled fluxes
    ``f`` (k, n), solid angles ``w`` and photon counts ``cnt`` (n) and the coarser level's
    intensities ``coarse`` (k, nc), looked up at the taps ``idx``, ``tw`` (4, n). The blend
    weights are ``weight`` (n) as given where ``replay``, else computed into it: the
    confidence ``min(1, max(count, expected) / threshold)``, and where ``adaptive`` raised
    in the groups (``parent``: each texel's coarse texel; ``canon_c``, ``shared_c``: the
    coarse level's seams) whose counts depart from the coarse prediction. ``canon``,
    ``shared``: this level's seams."""
    k, n = f.shape
    nc = coarse.shape[1]
    own = np.zeros((k, n))
    below = np.empty((k, n))
    for c in range(k):
        for i in range(n):
            if w[i] > 0:
                own[c, i] = f[c, i] / w[i]
            below[c, i] = _lookup(coarse[c], idx, tw, i)
    if not replay:
        expected = np.empty(n)
        for i in range(n):
            expected[i] = below[0, i] * w[i] * photons_per_lumen
            confidence = max(cnt[i], expected[i])
            weight[i] = min(1.0, confidence / threshold)
        if adaptive:
            _raise_where_biased(weight, own[0], below[0], expected, w, cnt, parent, idx, tw,
                                canon_c, shared_c, nc)
    value = np.empty((k, n))
    for c in range(k):
        for i in range(n):
            value[c, i] = weight[i] * own[c, i] + (1.0 - weight[i]) * below[c, i]
        _weld(value[c], w, canon, shared)
    return value


@numba.njit(**_JIT)
def _raise_where_biased(weight, own, below, expected, w, cnt, parent, idx, tw, canon_c,
                        shared_c, nc):
    """The weights raised where the coarse level is biased: per group of texels under one
    coarse texel, the counts' chi-square against the prediction beyond its mean by six
    standard deviations plus 6 marks a bias, whose amplitude (the texels' mean squared
    departure beyond noise), interpolated to the texels, weighs them by
    ``bias^2 / (bias^2 + noise^2)``."""
    n = w.shape[0]
    var_own = np.empty(n)
    dev = np.empty(n)
    ones = np.ones(n)
    chi = np.empty(n)
    for i in range(n):
        var_own[i] = below[i] * below[i] / max(expected[i], 1.0)
        d = own[i] - below[i]
        dev[i] = w[i] * (d * d - var_own[i])
        e = cnt[i] - expected[i]
        chi[i] = e * e / max(expected[i], 1.0)
    area = _group_sums(parent, w, nc)
    excess = _group_sums(parent, dev, nc)
    m = _group_sums(parent, ones, nc)
    chi2 = _group_sums(parent, chi, nc)
    bias = np.empty(nc)
    for g in range(nc):
        x = excess[g] / area[g] if area[g] > 0 else 0.0
        significant = chi2[g] > m[g] + 6.0 * math.sqrt(2.0 * m[g]) + 6.0
        bias[g] = math.sqrt(max(x, 0.0) if significant else 0.0)
    _weld(bias, area, canon_c, shared_c)
    for i in range(n):
        b = max(_lookup(bias, idx, tw, i), 0.0)
        b2 = b * b
        weight[i] = max(weight[i], b2 / max(b2 + var_own[i], 1e-300))
