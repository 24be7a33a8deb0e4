"""Warps from the unit square to directions and points, vectorised over photons.

Vectors are stored component-major, shape (3, N) float64: ``v[0]`` is every photon's x.
Each component is then one contiguous array, which makes numpy's elementwise maths,
``take`` and ``compress`` several times faster than on (N, 3) rows. Densities are per
steradian (or per unit area) and are stated on each function; chi-square tests check them.
"""
from __future__ import annotations

import numpy as np

TWO_PI = 2.0 * np.pi


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (3, N) vectors, (N,)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of (3, N) vectors."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along (3, N) vectors."""
    return v / np.sqrt(dot(v, v))


def cos_sin(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of angles (rad) evaluated in float32 (SIMD; 7 significant digits is
    ample for sampling angles) and returned as float64."""
    p = phi.astype(np.float32)
    return np.cos(p).astype(np.float64), np.sin(p).astype(np.float64)


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (t, b) completing unit normals ``n`` (3, N) to right-handed frames.

    Duff et al. 2017, "Building an orthonormal basis, revisited": branchless and continuous.
    """
    nx, ny, nz = n
    sign = np.copysign(1.0, nz)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    t = np.empty_like(n)
    bt = np.empty_like(n)
    t[0] = 1.0 + sign * nx * nx * a
    t[1] = sign * b
    t[2] = -sign * nx
    bt[0] = b
    bt[1] = sign + ny * ny * a
    bt[2] = -ny
    return t, bt


def to_world(local: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Rotate local (3, N) vectors (z along the normal) into the frames of unit normals ``n``."""
    t, b = orthonormal_basis(n)
    return local[0] * t + local[1] * b + local[2] * n


def cosine_hemisphere(u1: np.ndarray, u2: np.ndarray, sin2_max: float | np.ndarray = 1.0) -> np.ndarray:
    """Cosine-weighted directions about +z, restricted to theta <= theta_max, (3, N).

    pdf = cos(theta) / (pi * sin^2(theta_max)) per sr; ``sin2_max`` = 1 is the full hemisphere.
    """
    sin2 = u1 * sin2_max
    sin_t = np.sqrt(sin2)
    c, s = cos_sin(TWO_PI * u2)
    return np.stack([sin_t * c, sin_t * s, np.sqrt(np.maximum(0.0, 1.0 - sin2))])


def cosine_about(n: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions about unit normals ``n`` (3, N); pdf = cos / pi per sr.

    The same warp as ``to_world(cosine_hemisphere(u1, u2), n)``, fused for the hot path.
    """
    t, b = orthonormal_basis(n)
    sin_t = np.sqrt(u1)
    c, s = cos_sin(TWO_PI * u2)
    t *= sin_t * c
    b *= sin_t * s
    t += b
    t += np.sqrt(1.0 - u1) * n
    return t


def uniform_cone(u1: np.ndarray, u2: np.ndarray, cos_max: float = -1.0) -> np.ndarray:
    """Directions uniform in solid angle about +z within theta <= theta_max, (3, N).

    pdf = 1 / (2 pi (1 - cos_max)) per sr; ``cos_max`` = -1 is the whole sphere.
    """
    cos_t = 1.0 - u1 * (1.0 - cos_max)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    c, s = cos_sin(TWO_PI * u2)
    return np.stack([sin_t * c, sin_t * s, cos_t])


def uniform_disk(u1: np.ndarray, u2: np.ndarray, radius: float) -> np.ndarray:
    """Points uniform by area on the disk of ``radius`` in the z = 0 plane, (3, N)."""
    r = radius * np.sqrt(u1)
    c, s = cos_sin(TWO_PI * u2)
    return np.stack([r * c, r * s, np.zeros_like(r)])


def reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror directions ``d`` about unit normals ``n`` (3, N; either orientation)."""
    return d - (2.0 * dot(d, n)) * n
