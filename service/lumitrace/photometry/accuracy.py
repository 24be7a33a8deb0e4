"""How accurate the photometric files are, from their own counts: the relative RMS standard
error of the published grid over the sphere, and its worst lit value's, which a target error
is judged on by default (the map's own error being the other choice).

The grid's variances are exact (binomial, analog photons), so the RMS needs no bound of its
own beyond taking the noise out of the signal it is relative to. A target ``E`` is met when
the RMS is within ``E`` and no lit value (at least :data:`LIT_SHARE` of the largest) has a
relative standard error above :data:`WORST_FACTOR` times ``E``: a file whose nadir or peak
is far noisier than the rest is not converged, whatever its RMS.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .grid import CGammaGrid
from .measured import LIT_SHARE, cell_solid_angle_grid

#: A lit value's relative standard error may be this many times the target error.
WORST_FACTOR = 3.0


@dataclass(frozen=True)
class FilesAccuracy:
    """The published grid's relative RMS standard error over the sphere (``rms``; ``bound``
    the same relative to the signal with its noise taken out), the largest relative standard
    error of a lit value (``worst``) and where it is (C, gamma deg); None where no light
    escaped."""

    rms: float | None
    bound: float | None
    worst: float | None
    worst_at: tuple[float, float] | None = None

    def meets(self, target: float) -> bool:
        """Whether the files are converged at ``target`` (relative). A stronger symmetry
        more photons may still show does not hold it back: the files of the symmetry
        shown are unbiased and their error stated; a stronger one shown later only
        averages more planes, which lowers it."""
        return (self.bound is not None and self.worst is not None
                and self.bound <= target and self.worst <= WORST_FACTOR * target)

    @property
    def error(self) -> float:
        """The error a target is compared with: the bound, or the worst lit value's over
        :data:`WORST_FACTOR`, whichever asks more (infinite where undefined)."""
        if self.bound is None or self.worst is None:
            return math.inf
        return max(self.bound, self.worst / WORST_FACTOR)


def grid_accuracy(grid: CGammaGrid, c_step: float) -> FilesAccuracy:
    """The accuracy of a measured grid (with ``sigma``), planes every ``c_step`` deg."""
    full = grid.full()
    omega = cell_solid_angle_grid(full.gamma, c_step)
    cd, sigma = full.candela, full.sigma
    signal = float((omega * cd ** 2).sum())
    noise = float((omega * sigma ** 2).sum())
    if signal <= 0:
        return FilesAccuracy(None, None, None)
    rms = math.sqrt(noise / signal)
    bound = math.sqrt(noise / (signal - noise)) if signal > noise else math.inf
    lit = cd >= LIT_SHARE * float(cd.max())
    rel = np.where(lit, sigma / np.where(lit, cd, 1.0), 0.0)
    i, j = np.unravel_index(int(np.argmax(rel)), rel.shape)
    return FilesAccuracy(rms, bound, float(rel[i, j]), (float(full.c[i]), float(full.gamma[j])))
