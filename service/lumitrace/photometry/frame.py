"""The photometric frame of type C photometry in the stage's axes.

Nadir (gamma = 0) is the stage's down direction, -upAxis; C = 0 lies along the stage's +X
axis and C grows counter-clockwise seen from above, so C = 90 is the axis that completes a
right-handed frame (X, C90, up): +Y in a Z-up stage, -Z in a Y-up stage.
"""
from __future__ import annotations

import numpy as np

UP_VECTORS = {"Z": np.array([0.0, 0.0, 1.0]), "Y": np.array([0.0, 1.0, 0.0])}


def axes(up_axis: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit vectors (C0, C90, up) of the photometric frame of a stage with ``up_axis``."""
    up = UP_VECTORS[up_axis]
    c0 = np.array([1.0, 0.0, 0.0])
    c90 = np.cross(up, c0)
    return c0, c90, up


def directions(c_deg: np.ndarray, gamma_deg: np.ndarray, up_axis: str) -> np.ndarray:
    """Unit directions (..., 3) in stage axes of the angle pairs (C, gamma) in degrees."""
    c0, c90, up = axes(up_axis)
    c = np.radians(c_deg)[..., None]
    g = np.radians(gamma_deg)[..., None]
    return np.sin(g) * (np.cos(c) * c0 + np.sin(c) * c90) - np.cos(g) * up


def angles(d: np.ndarray, up_axis: str) -> tuple[np.ndarray, np.ndarray]:
    """(C, gamma) in degrees of directions ``d`` (N, 3); C in [0, 360)."""
    c0, c90, up = axes(up_axis)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    gamma = np.degrees(np.arccos(np.clip(-(d @ up), -1.0, 1.0)))
    c = np.degrees(np.arctan2(d @ c90, d @ c0)) % 360.0
    return c, gamma
