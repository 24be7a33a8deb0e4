"""Warps from the unit square to directions and points, vectorised over (N,) arrays.

All directions are unit float64 vectors, shape (N, 3). Densities are per steradian (or per
unit area) and are stated on each function; the chi-square tests check them.
"""
from __future__ import annotations

import numpy as np


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (t, b) completing unit normals ``n`` (N,3) to right-handed frames.

    Duff et al. 2017, "Building an orthonormal basis, revisited": branchless and continuous.
    """
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bt = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, bt


def to_world(local: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Rotate local vectors (z along the normal) into the frame of unit normals ``n``."""
    t, b = orthonormal_basis(n)
    return local[:, 0:1] * t + local[:, 1:2] * b + local[:, 2:3] * n


def cosine_hemisphere(u1: np.ndarray, u2: np.ndarray, sin2_max: float | np.ndarray = 1.0) -> np.ndarray:
    """Cosine-weighted directions about +z, restricted to theta <= theta_max.

    pdf = cos(theta) / (pi * sin^2(theta_max)) per sr; ``sin2_max`` = 1 is the full hemisphere.
    """
    sin2 = u1 * sin2_max
    sin_t = np.sqrt(sin2)
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2))
    phi = 2.0 * np.pi * u2
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)


def uniform_cone(u1: np.ndarray, u2: np.ndarray, cos_max: float = -1.0) -> np.ndarray:
    """Directions uniform in solid angle about +z within theta <= theta_max.

    pdf = 1 / (2 pi (1 - cos_max)) per sr; ``cos_max`` = -1 is the whole sphere.
    """
    cos_t = 1.0 - u1 * (1.0 - cos_max)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * np.pi * u2
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)


def uniform_disk(u1: np.ndarray, u2: np.ndarray, radius: float) -> np.ndarray:
    """Points uniform by area on the disk of ``radius`` in the z = 0 plane, (N, 3)."""
    r = radius * np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.zeros_like(r)], axis=1)


def reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror directions ``d`` about unit normals ``n`` (either orientation)."""
    return d - 2.0 * np.einsum("ij,ij->i", d, n)[:, None] * n


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the rows of ``v`` (N, 3)."""
    return v / np.linalg.norm(v, axis=1, keepdims=True)
