"""Sampling tables of measured intensity profiles (IES LM-63, EULUMDAT) on emitters.

A profile file is read once (cached by path, size and modification time) and expanded to
a fine table over the light's own directions: C in steps of at most 1.25 deg (a quarter of
the file's own step, or one column for a rotationally symmetric profile) by gamma in
0.05 deg steps. Each cell holds the flux of the profile over it, with the intensity at the
cell's centre interpolated from the file as photometric readers do (linear in C between
planes, linear in gamma between angles, the file's symmetry expanded; nothing outside the
file's gamma range). Photons pick a column, then a row, by inverse CDF, and a direction
uniform in solid angle within the cell. ``ies:angleScale`` maps the light's angle to the
file's as UsdLux defines it: gamma_ies = (gamma - 180) / (1 + angleScale) + 180 deg.
"""
from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import LumitraceError
from ..photometry.eulumdat import read_ldt
from ..photometry.grid import CGammaGrid
from ..photometry.lm63 import read_ies
from ..scene import IesShaping

#: Fine table steps (deg): gamma, and the most a C column may span.
GAMMA_STEP = 0.05
C_STEP_MAX = 1.25


@dataclass(frozen=True)
class ProfileTable:
    """Inverse-CDF tables of one profile: the C columns' CDF (n_c + 1), every column's
    gamma CDF (n_c, n_g + 1), the cosines of the gamma edges (n_g + 1), the column width
    (rad), and the profile's flux per unit of its candela values (sr)."""

    c_cdf: np.ndarray
    gamma_cdf: np.ndarray
    cos_edges: np.ndarray
    c_step: float
    solid_angle_integral: float


def read_profile(path: str) -> tuple[CGammaGrid, float, float]:
    """The file's C-gamma grid (cd) and its gamma range (deg): IES LM-63, or EULUMDAT by
    the ``.ldt`` extension."""
    try:
        if path.lower().endswith(".ldt"):
            ldt = read_ldt(path)
            return ldt.grid, float(ldt.gammas[0]), float(ldt.gammas[-1])
        ies = read_ies(path)
        return ies.grid(), float(ies.vertical[0]), float(ies.vertical[-1])
    except LumitraceError as exc:
        raise LumitraceError(f"cannot use the IES profile: {exc}", path) from None
    except (OSError, ValueError) as exc:
        raise LumitraceError(f"cannot read the IES profile: {exc}", path) from None


def profile_table(ies: IesShaping) -> ProfileTable:
    """The sampling table of ``ies`` (re-read when the file changes)."""
    try:
        st = os.stat(ies.file)
    except OSError as exc:
        raise LumitraceError(f"cannot read the IES profile: {exc.strerror}", ies.file) from None
    return _table(ies, st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=32)
def _table(ies: IesShaping, _mtime_ns: int, _size: int) -> ProfileTable:
    grid, g_lo, g_hi = read_profile(ies.file)
    if grid.symmetry == "rotational":
        n_c = 1
    else:
        planes = np.unique(np.mod(grid.full().c, 360.0))
        step = float(np.min(np.diff(planes))) if len(planes) > 1 else 360.0
        n_c = int(math.ceil(360.0 / min(C_STEP_MAX, step / 4.0)))
    c_step = 360.0 / n_c
    n_g = int(round(180.0 / GAMMA_STEP))
    edges = np.linspace(0.0, 180.0, n_g + 1)
    centres = 0.5 * (edges[1:] + edges[:-1])
    g_file = (centres - 180.0) / (1.0 + ies.angle_scale) + 180.0  # UsdLux ies:angleScale
    inside = (g_file >= g_lo) & (g_file <= g_hi)
    rows = grid.at((np.arange(n_c) + 0.5) * c_step)  # (n_c, file gammas), linear in C
    j = np.clip(np.searchsorted(grid.gamma, g_file, side="right") - 1, 0, len(grid.gamma) - 2)
    span = grid.gamma[j + 1] - grid.gamma[j]
    t = np.clip(np.divide(g_file - grid.gamma[j], span, out=np.zeros_like(span),
                          where=span > 0), 0.0, 1.0)
    cd = (rows[:, j] * (1.0 - t) + rows[:, j + 1] * t) * inside
    if (cd < 0).any() or not np.isfinite(cd).all():
        raise LumitraceError("the IES profile has negative or non-finite candela values",
                             ies.file)
    cos_edges = np.cos(np.radians(edges))
    w = cd * (cos_edges[:-1] - cos_edges[1:]) * math.radians(c_step)
    col = w.sum(axis=1)
    total = float(col.sum())
    if not total > 0.0:
        raise LumitraceError("the IES profile emits nothing", ies.file)
    c_cdf = np.concatenate([[0.0], np.cumsum(col)]) / total
    cum = np.concatenate([np.zeros((n_c, 1)), np.cumsum(w, axis=1)], axis=1)
    gamma_cdf = np.where(col[:, None] > 0, cum / np.where(col > 0, col, 1.0)[:, None],
                         np.linspace(0.0, 1.0, n_g + 1)[None, :])
    c_cdf[-1] = 1.0
    gamma_cdf[:, -1] = 1.0
    return ProfileTable(c_cdf, np.ascontiguousarray(gamma_cdf), cos_edges,
                        math.radians(c_step), total)
