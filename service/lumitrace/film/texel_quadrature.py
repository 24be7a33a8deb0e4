"""Integrals of a far-field function over every cube-map texel footprint.

Turns a closed-form intensity I(direction) (cd) into the map an ideal, noise-free tracer
would produce: the footprint average ``integral(I dOmega) / Omega_texel``. Used to compare
traced maps with analytic references without any sampling error in the reference.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from .cubemap import (FACE_AXIS, FACE_MINOR_AXES, FACE_SIGN, NUM_FACES, _footprint_bounds,
                      image_shape, pixel_position)


def texel_integrals(f: Callable[[np.ndarray], np.ndarray], res: int, order: int = 6) -> np.ndarray:
    """``integral over texel footprint of f(omega) dOmega`` for every texel, (6R, R).

    ``f`` maps unit directions (N, 3) to values (N,); each footprint is integrated with an
    ``order`` x ``order`` Gauss-Legendre rule in face coordinates, where
    ``dOmega = da db / (1 + a^2 + b^2)^(3/2)``.
    """
    bounds = _footprint_bounds(res)
    x, w = np.polynomial.legendre.leggauss(order)
    lo, hi = bounds[:-1], bounds[1:]
    # (res, order) quadrature nodes and weights per pixel interval
    nodes = 0.5 * (hi - lo)[:, None] * x[None, :] + 0.5 * (hi + lo)[:, None]
    weights = 0.5 * (hi - lo)[:, None] * w[None, :]
    a = nodes[None, :, None, :]      # px index i, node k
    b = nodes[:, None, :, None]      # py index j, node l
    wa = weights[None, :, None, :]
    wb = weights[:, None, :, None]
    a, b = np.broadcast_arrays(a, b)
    jac = (wa * wb) / (1.0 + a * a + b * b) ** 1.5
    out = np.zeros(image_shape(res))
    py_idx, px_idx = np.meshgrid(np.arange(res), np.arange(res), indexing="ij")
    for face in range(NUM_FACES):
        d = np.empty(a.shape + (3,))
        d[..., FACE_AXIS[face]] = FACE_SIGN[face]
        d[..., FACE_MINOR_AXES[face][0]] = a
        d[..., FACE_MINOR_AXES[face][1]] = b
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        vals = f(d.reshape(-1, 3)).reshape(a.shape) * jac
        per_pixel = vals.sum(axis=(2, 3))  # [py, px]
        pos = pixel_position(np.full(res * res, face),
                             np.stack([px_idx.ravel(), py_idx.ravel()], axis=-1), res)
        cols = np.rint(pos[:, 0]).astype(np.int64)
        rows = np.rint(pos[:, 1]).astype(np.int64)
        out[rows, cols] = per_pixel.ravel()
    return out
