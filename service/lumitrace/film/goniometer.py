"""The virtual goniophotometer: escaping photons counted by direction in C-gamma cells of the
luminaire's photometric frame, and by where they leave the luminaire's bounding box.

The cube map serves the interactive preview; the photometric files come from these counts.
A cell's photon flux over its solid angle is an unbiased estimate of the cell's mean
intensity, and exports add whole cells, so every value an IES or LDT file holds has no bias
beyond the averaging over its own cell (as a goniophotometer's detector aperture averages).

Cells are 1.25 deg of C by 0.25 deg of gamma, with extra gamma edges at the CIE flux code's
zone boundaries (cos gamma = 0.75, 0.25; 60 deg is on the grid), so every C step that is a
multiple of 2.5 deg, every gamma grid in 0.5 deg steps and every CIE zone is a sum of whole
cells. The exit tally bins each escaping photon's crossing of the luminaire's bounding box
(in the photometric frame) on a 32 x 32 grid per face: the luminous opening is measured from
it, not guessed from the geometry.

All counts live in one array of :data:`N_BINS` bins: first the C-gamma cells (C-major:
``c_bin * N_GAMMA + gamma_bin``), then the exit bins (``face * 1024 + row * 32 + col``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene.model import point_bounds

#: Width of a C cell (deg) and of a gamma cell (deg).
C_STEP = 1.25
GAMMA_STEP = 0.25
#: cos(gamma) of the CIE flux code's cone boundaries (solid angles pi/2, pi, 3 pi/2 sr).
CIE_COSINES = (0.75, 0.5, 0.25)
_RASTER = np.arange(0.0, 180.0 + 1e-9, GAMMA_STEP)
_OFF_RASTER = np.array(sorted(set(np.round(np.degrees(np.arccos(CIE_COSINES)), 12).tolist())
                              - set(_RASTER.tolist())))
#: Gamma cell edges (deg), 0 to 180 (merged by hand: numpy's set routines load numpy.ma,
#: about 20 ms of a run's start).
GAMMA_EDGES = np.sort(np.concatenate([_RASTER, _OFF_RASTER]))
N_C = int(round(360.0 / C_STEP))
N_GAMMA = len(GAMMA_EDGES) - 1
N_CELLS = N_C * N_GAMMA
#: Exit bins per face side, faces of the box, exit bins in all.
EXIT_SIDE = 32
FACES = ("bottom", "top", "-C0", "+C0", "-C90", "+C90")
N_EXIT = len(FACES) * EXIT_SIDE * EXIT_SIDE
N_BINS = N_CELLS + N_EXIT
#: The two in-face coordinates (photometric axes 0 = C0, 1 = C90, 2 = up) of each face.
FACE_AXES = ((0, 1), (0, 1), (1, 2), (1, 2), (0, 2), (0, 2))
#: The gamma edges that are not on the uniform raster (the CIE zones'), in degrees: a
#: gamma's cell is its raster cell plus the number of these at or below it. The tracer's
#: kernel (:func:`lumitrace.trace.kernels.gonio_bins`) bins escaping photons so.
EXTRA_EDGES = _OFF_RASTER
# the kernels carry them in registers, as four at most (kernels._edges4)
if len(EXTRA_EDGES) > 4:  # pragma: no cover - a change of the grid or the CIE zones
    raise ImportError(f"{len(EXTRA_EDGES)} off-raster gamma edges; the kernels take 4")


def escape_bins(cell: np.ndarray, exit_bin: np.ndarray, half: np.ndarray) -> np.ndarray:
    """The flat bins of escaped photons (each counted in its cell and its exit bin, the
    latter offset by N_CELLS; + N_BINS in the second half) that
    :func:`~lumitrace.film.accumulate.counts_of` turns into a tally's counts."""
    return np.concatenate([cell, exit_bin]) + N_BINS * np.tile(half, 2)


def cell_solid_angles() -> np.ndarray:
    """Solid angle (sr) of every C-gamma cell, (N_C, N_GAMMA); they sum to 4 pi."""
    zone = -np.diff(np.cos(np.radians(GAMMA_EDGES)))
    return np.radians(C_STEP) * np.broadcast_to(zone, (N_C, N_GAMMA))


@dataclass(frozen=True)
class Goniometer:
    """Where an escaping photon is counted: ``axes`` are the rows (C0, C90, up) of the
    photometric frame in world axes; ``lo``, ``hi`` the luminaire's bounding box (m) in
    those axes, pinned for a session like the tracing frame."""

    axes: tuple
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    @classmethod
    def around(cls, axes: np.ndarray, points: np.ndarray) -> "Goniometer":
        """The goniometer whose box holds ``points`` (N, 3, world m)."""
        a = np.asarray(axes, np.float64)
        q = np.asarray(points, np.float64).reshape(-1, 3) @ a.T
        if not len(q):
            q = np.zeros((1, 3))
        lo, hi = point_bounds(q)
        return cls(tuple(map(tuple, a.tolist())), tuple(map(float, lo)), tuple(map(float, hi)))

    @classmethod
    def of(cls, scene) -> "Goniometer":
        """The goniometer of a :class:`~lumitrace.scene.Scene`: its photometric axes, the
        box of its geometry and emitters."""
        return cls.around(scene.photometric_axes, scene.shape_points())
