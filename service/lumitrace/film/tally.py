"""The batch tally: what one batch of photons did, in exact integer counts.

The tracer fills it; the accumulators own it: they add a batch's tally and can take it
out again exactly, so a batch's photons can be retraced after an edit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np



@dataclass
class BatchTally:
    """Escapes per texel and where the rest of one batch's photons went.

    ``counts`` is (2, texels) int64: escapes of the photons in each of two pseudo-random
    halves (split by the photon hash), two independent estimates of the same map.
    ``cells`` is (2, :data:`~lumitrace.film.goniometer.N_BINS`) int64, the same photons
    counted by the virtual goniophotometer (C-gamma cell and exit bin each), dense or
    :class:`~lumitrace.film.accumulate.SparseCounts`; None when none escaped.
    ``emitter``, ``start`` and ``photons`` name the batch (emitter number, first photon
    index, photon count); ``segments`` counts traced path segments (rays).
    In a spectral scene ``xz`` holds the escapes' X and Z tallies: ``(x_counts, z_counts,
    x_cells, z_cells)``, each (2, n) int64 like ``counts`` (texels) and the C-gamma cells
    (:data:`~lumitrace.film.goniometer.N_CELLS`), in units of
    1/:data:`~lumitrace.scene.spectra.FIXED_POINT` of a photon's Y.
    """

    emitter: int
    start: int
    photons: int
    counts: np.ndarray
    cells: np.ndarray | None = None
    absorbed: int = 0
    cut: int = 0
    segments: int = 0
    rays: list | None = None
    records: object | None = None  # the photons' PhotonRecords, when asked for
    part_hits: np.ndarray | None = None  # surface hits per part (Scene.parts order)
    exit_rays: tuple | None = None  # (positions, directions) of the escapes, when asked for
    xz: tuple | None = None  # spectral scenes: X and Z tallies (see above)

    @property
    def escaped(self) -> int:
        return int(self.counts.sum())

    @classmethod
    def empty(cls, emitter: int, start: int, photons: int, resolution: int,
              record_rays: bool = False) -> "BatchTally":
        """A zero tally for a batch, ready to be filled (``rays`` kept on request)."""
        ntex = 6 * resolution * resolution
        return cls(emitter, start, photons, np.zeros((2, ntex), np.int64),
                   rays=[] if record_rays else None)
