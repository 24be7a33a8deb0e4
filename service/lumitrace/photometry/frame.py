"""The photometric frame of type C photometry.

Nadir (gamma = 0) is the luminaire's down direction; C = 0 lies along its +X axis and C grows
counter-clockwise seen from above, so C = 90 is the axis that completes a right-handed frame
(C0, C90, up). For a luminaire prim with no rotation of its own these are the stage's axes:
C90 is +Y in a Z-up stage, -Z in a Y-up stage. See :func:`lumitrace.scene.photometric_axes`.
"""
from __future__ import annotations

import numpy as np

from ..scene.model import photometric_axes


def axes(up_axis: str, rotation=()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit vectors (C0, C90, up) of the photometric frame, in world axes."""
    c0, c90, up = photometric_axes(up_axis, rotation)
    return c0, c90, up


def directions(c_deg: np.ndarray, gamma_deg: np.ndarray, up_axis: str,
               rotation=()) -> np.ndarray:
    """Unit directions (..., 3) in world axes of the angle pairs (C, gamma) in degrees."""
    c0, c90, up = axes(up_axis, rotation)
    c = np.radians(c_deg)[..., None]
    g = np.radians(gamma_deg)[..., None]
    return np.sin(g) * (np.cos(c) * c0 + np.sin(c) * c90) - np.cos(g) * up


def angles(d: np.ndarray, up_axis: str, rotation=()) -> tuple[np.ndarray, np.ndarray]:
    """(C, gamma) in degrees of directions ``d`` (N, 3); C in [0, 360)."""
    c0, c90, up = axes(up_axis, rotation)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    gamma = np.degrees(np.arccos(np.clip(-(d @ up), -1.0, 1.0)))
    c = np.degrees(np.arctan2(d @ c90, d @ c0)) % 360.0
    return c, gamma


def luminaire_rotation(scene) -> np.ndarray | tuple:
    """The 3x3 world rotation (with scale) of a scene's luminaire prim, or () for none: the
    ``rotation`` argument of the functions above."""
    m = scene.luminaire_to_world
    return np.asarray(m)[:3, :3] if len(m) else ()
