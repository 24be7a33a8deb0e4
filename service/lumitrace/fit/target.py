"""The target distribution a fit matches: an IES LM-63 or EULUMDAT file, read once.

Its grid is taken as the file states it (candela for its lamps; a point value a little
below zero where a measured file's noise put it there), its symmetry as the file declares
it (IES by its horizontal angles, EULUMDAT by its symmetry indicator), and zero outside its
gamma range (an IES file of a downlight often stops at 90 deg).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import LumitraceError
from ..photometry.eulumdat import read_ldt
from ..photometry.grid import CGammaGrid
from ..photometry.lm63 import read_ies
from .parameters import FitError


@dataclass(frozen=True)
class Target:
    """A target distribution: ``grid`` (cd, the file's symmetry), its gamma range (deg),
    its lamp flux (lm) and the file it came from."""

    grid: CGammaGrid
    gamma_lo: float
    gamma_hi: float
    lamp_flux: float
    path: str

    @property
    def symmetry(self) -> str:
        return self.grid.symmetry

    def values(self, c_deg: np.ndarray, gamma_deg: np.ndarray) -> np.ndarray:
        """The target's intensity (cd) at every (C, gamma) of a grid, (len(c), len(gamma)):
        linear between the file's planes and angles, its symmetry unfolded, 0 outside its
        gamma range."""
        rows = self.grid.at(np.asarray(c_deg, np.float64))  # (len(c), file gammas)
        g = np.asarray(gamma_deg, np.float64)
        out = np.array([np.interp(g, self.grid.gamma, row) for row in rows])
        out[:, (g < self.gamma_lo - 1e-9) | (g > self.gamma_hi + 1e-9)] = 0.0
        return out

    def half_width(self) -> float | None:
        """Half-angle (deg from the peak's gamma, outward) where the mean profile over C
        falls to half of its peak; None where it never does."""
        g = np.asarray(self.grid.gamma, np.float64)
        rows = self.grid.at(np.arange(0.0, 360.0, 5.0))
        profile = rows.mean(axis=0)
        k = int(np.argmax(profile))
        below = np.flatnonzero(profile[k:] < 0.5 * profile[k])
        if not below.size:
            return None
        j = k + int(below[0])
        # linear between the last value above half and the first below
        a, b = profile[j - 1], profile[j]
        cross = g[j - 1] + (a - 0.5 * profile[k]) / (a - b) * (g[j] - g[j - 1])
        return float(cross - g[k])

    def as_dict(self) -> dict:
        return {"file": self.path, "symmetry": self.symmetry, "lamp_flux": self.lamp_flux,
                "gamma_range": [self.gamma_lo, self.gamma_hi]}


def read_target(path: str | os.PathLike) -> Target:
    """The target in ``path`` (``.ldt``: EULUMDAT, else IES LM-63); a :class:`FitError`
    naming the file when it cannot be read or holds no light."""
    p = Path(path)
    where = f"--target {p}"
    if not p.is_file():
        raise FitError("no such file" if not p.exists() else "is not a regular file", where)
    try:
        if p.suffix.lower() == ".ldt":
            ldt = read_ldt(p)
            grid, lamp_flux = ldt.grid, float(ldt.lamp_flux)
        else:
            ies = read_ies(p)
            grid = ies.grid()
            lamp_flux = float(ies.lamps * ies.lumens_per_lamp)
    except LumitraceError as exc:
        raise FitError(f"cannot read the target: {exc.message}", where) from None
    except (OSError, ValueError, IndexError, KeyError) as exc:
        raise FitError(f"cannot read the target: {exc}", where) from None
    cd = np.asarray(grid.candela, np.float64)
    g = np.asarray(grid.gamma, np.float64)
    if cd.size == 0 or g.size < 2 or not np.all(np.isfinite(cd)) or not np.all(np.diff(g) > 0):
        raise FitError("cannot read the target: its gamma angles must rise and its values "
                       "be finite numbers", where)
    if not (cd > 0).any():
        raise FitError("the target holds no light (every intensity is 0)", where)
    return Target(grid, float(g[0]), float(g[-1]), lamp_flux, str(p))
