"""The photometric description of a traced result, measured by the virtual goniophotometer:
the C-gamma grid with its standard errors and symmetry, the figures and the luminous
opening, ready for the IES and EULUMDAT writers, the pictures and the sidecar JSON."""
from __future__ import annotations

from dataclasses import dataclass, replace

import math

import numpy as np

from ..film.accumulate import Accumulator
from ..film.goniometer import (EXIT_SIDE, FACE_AXES, FACES, GAMMA_EDGES, N_CELLS, N_EXIT,
                               N_GAMMA, cell_solid_angles)
from ..scene import Scene
from .grid import CGammaGrid, default_gammas
from .accuracy import FilesAccuracy, grid_accuracy
from .measured import SymmetryChoice, emitter_rings, symmetric_grid
from .quantities import PhotometricFigures, figures, scaled_figures

#: A symmetry the geometry does not show is used where the counts show the departure from
#: it within this (relative RMS, at its 3 sigma upper bound; see
#: :func:`~lumitrace.photometry.measured.departure`).
SYMMETRY_TOLERANCE = 0.01
#: C step (deg) of the published grid.
C_STEP = 5.0
#: Share of the exiting flux left out at each end of the opening's extent (its edges are
#: where all but this much of the light has left).
OPENING_TAIL = 0.001
#: Below this share of the escaping flux, the sides of the box have no luminous height.
SIDE_SHARE = 0.01


@dataclass(frozen=True)
class LuminousOpening:
    """Luminous dimensions (m) in the photometric frame, along C0, along C90 and vertical,
    and the opening's centre (m, photometric-frame coordinates): measured from where
    escaping photons cross the luminaire's bounding box."""

    length: float
    width: float
    height: float
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: the opening is round (a circle where length equals width, else an ellipse): the
    #: light leaves its face within the ellipse inscribed in the extents
    round: bool = False
    #: the luminaire's own extents (m) along C0, C90 and vertical (its bounding box)
    box: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def area(self) -> float:
        """The luminous area (m^2) of the flat opening: an ellipse's or a rectangle's."""
        return (math.pi / 4.0 if self.round else 1.0) * self.length * self.width


def _extent(marginal: np.ndarray, lo: float, hi: float) -> tuple[float, float]:
    """(start, end) between which all but :data:`OPENING_TAIL` of a binned distribution
    (``marginal`` over ``lo`` .. ``hi``) lies at each end, linear within bins."""
    total = float(marginal.sum())
    if total <= 0 or hi <= lo:
        return lo, hi
    cum = np.concatenate([[0.0], np.cumsum(marginal)]) / total
    edges = np.linspace(lo, hi, len(marginal) + 1)
    return (float(np.interp(OPENING_TAIL, cum, edges)),
            float(np.interp(1.0 - OPENING_TAIL, cum, edges)))


#: A flat opening is round when at most this share of the light leaving its face leaves
#: through bins wholly outside the ellipse inscribed in its extents (a square opening sends
#: about a fifth of its light through the corners; the bins' size blurs a circle's edge).
ROUND_OPENING_OUTSIDE = 0.02


def luminous_opening(acc: Accumulator) -> LuminousOpening:
    """The luminous opening from the goniophotometer's exit bins: length and width are the
    extents (along C0, C90) of the crossings of the box's bottom face (its top face for a
    luminaire that sends more light up), the height the vertical extent of the crossings
    of its sides, 0 where they carry less than :data:`SIDE_SHARE` of the flux (LM-63's flat
    opening)."""
    g = acc.goniometer
    flux = np.zeros(N_EXIT)
    for w, _, values, idx in acc.emitter_cells():
        if idx is None:
            flux += w * values[N_CELLS:]
        else:
            keep = idx >= N_CELLS
            flux[idx[keep] - N_CELLS] += w * values[keep]
    return opening_of_faces(flux.reshape(len(FACES), EXIT_SIDE, EXIT_SIDE), g.lo, g.hi)


def opening_of_exits(positions: np.ndarray, flux: np.ndarray, lo, hi) -> LuminousOpening:
    """The luminous opening of exit rays (``positions`` (N, 3) on the box ``lo``, ``hi``,
    m in the photometric frame, ``flux`` lm each), binned on the box's faces as the
    goniophotometer bins them and measured by the same rule as :func:`luminous_opening`."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    p = np.asarray(positions, np.float64)
    # distance to each face's plane, in FACES' order: bottom, top, -C0, +C0, -C90, +C90
    gap = np.abs(np.stack([p[:, 2] - lo[2], p[:, 2] - hi[2], p[:, 0] - lo[0],
                           p[:, 0] - hi[0], p[:, 1] - lo[1], p[:, 1] - hi[1]], axis=1))
    face = np.argmin(gap, axis=1)
    axes = np.array(FACE_AXES)[face]
    span = np.maximum(hi - lo, 1e-12)
    rel = (p - lo) / span
    rows = np.arange(len(p))
    col = np.clip((rel[rows, axes[:, 0]] * EXIT_SIDE).astype(np.int64), 0, EXIT_SIDE - 1)
    row = np.clip((rel[rows, axes[:, 1]] * EXIT_SIDE).astype(np.int64), 0, EXIT_SIDE - 1)
    binned = np.bincount((face * EXIT_SIDE + row) * EXIT_SIDE + col,
                         np.asarray(flux, np.float64), N_EXIT)
    return opening_of_faces(binned.reshape(len(FACES), EXIT_SIDE, EXIT_SIDE), lo, hi)


def opening_of_faces(flux: np.ndarray, lo, hi) -> LuminousOpening:
    """The luminous opening from the exit flux per face bin (``flux`` (faces, rows, cols) in
    :data:`~lumitrace.film.goniometer.FACES`' order) of the box ``lo``, ``hi`` (m)."""
    lo, hi = np.array(lo, np.float64), np.array(hi, np.float64)
    box = tuple(float(x) for x in hi - lo)
    total = float(flux.sum())
    if total <= 0:
        return LuminousOpening(*(hi - lo), tuple(0.5 * (lo + hi)), box=box)
    face = 0 if flux[0].sum() >= flux[1].sum() else 1
    level = lo[2] if face == 0 else hi[2]
    f = flux[face]  # rows along C90, columns along C0
    if f.sum() < SIDE_SHARE * total:  # next to nothing leaves through top or bottom
        a0, b0, a1, b1 = lo[0], hi[0], lo[1], hi[1]
    else:
        a0, b0 = _extent(f.sum(axis=0), lo[0], hi[0])
        a1, b1 = _extent(f.sum(axis=1), lo[1], hi[1])
    sides = flux[2:]
    height = 0.0
    if sides.sum() >= SIDE_SHARE * total:
        a2, b2 = _extent(sides.sum(axis=(0, 2)), lo[2], hi[2])
        height = b2 - a2
    round_ = f.sum() >= SIDE_SHARE * total and \
        _outside_ellipse(f, (a0, b0, a1, b1), lo, hi) <= ROUND_OPENING_OUTSIDE
    return LuminousOpening(b0 - a0, b1 - a1, height, (0.5 * (a0 + b0), 0.5 * (a1 + b1), level),
                           round=bool(round_), box=box)


def _outside_ellipse(face: np.ndarray, extents, lo, hi) -> float:
    """Share of a face's exit flux (bins: rows along C90, columns along C0) whose bin lies
    wholly outside the ellipse inscribed in ``extents`` (a0, b0, a1, b1)."""
    a0, b0, a1, b1 = extents
    n = face.shape[0]
    e0, e1 = np.linspace(lo[0], hi[0], n + 1), np.linspace(lo[1], hi[1], n + 1)
    c0, r0 = 0.5 * (a0 + b0), 0.5 * (b0 - a0)
    c1, r1 = 0.5 * (a1 + b1), 0.5 * (b1 - a1)
    if r0 <= 0 or r1 <= 0:
        return 1.0
    # the bin's point nearest the ellipse's centre
    near0 = np.clip(c0, e0[:-1], e0[1:])
    near1 = np.clip(c1, e1[:-1], e1[1:])
    outside = ((near1[:, None] - c1) / r1) ** 2 + ((near0[None, :] - c0) / r0) ** 2 > 1.0
    total = float(face.sum())
    return float(face[outside].sum()) / total if total > 0 else 1.0


@dataclass(frozen=True)
class Photometry:
    """The photometric description of a result: the published C-gamma grid (reduced to the
    symmetry the counts hold, with standard errors), the figures, the luminous opening, the
    emitters' flux and each symmetry's estimated departure."""

    grid: CGammaGrid
    figures: PhotometricFigures
    opening: LuminousOpening
    lamp_flux: float
    symmetry: SymmetryChoice

    @property
    def departures(self) -> dict:
        """Each stronger symmetry tried: its departure's estimate (relative RMS)."""
        return {name: b[0] for name, b in self.symmetry.departures.items()}


def beam_half_width(rings: list[tuple[float, float, np.ndarray]]) -> float | None:
    """Half-angle (deg from the axis) where the mean profile over all C (0.5 deg rings)
    falls, past its peak, to half of the peak, from the emitters' rings
    (:func:`~lumitrace.photometry.measured.emitter_rings`); None where it never does.
    Chooses the grid's gammas and sizes the peak's fit.

    Read on what the photons show: the peak is the ring whose level is highest at its
    lower bound, and a ring counts as below half of it only where its upper bound is
    (3 standard errors each, one photon added to each ring's count). A flat top (a
    cup's direct light, level to its cut-off) has its highest ring anywhere on it, by
    chance: measured from that ring, its half width would flip from run to run between
    the cut-off's angle and a few degrees, and the files' gammas with it between the
    default and the fine raster."""
    flux = sum((w * ring for w, _, ring in rings), np.zeros(N_GAMMA))
    if not np.any(flux):
        return None
    # a ring's count as Poisson, one photon added: an empty ring near a pole is not
    # surely dark
    var = sum((w * w * (ring + 1.0) for w, _, ring in rings), np.zeros(N_GAMMA))
    bins = np.searchsorted(GAMMA_EDGES, np.arange(0.0, 180.0 + 1e-9, 0.5) - 1e-9)[:-1]
    omega = np.add.reduceat(cell_solid_angles().sum(axis=0), bins)
    prof = np.add.reduceat(flux, bins) / omega
    sigma = np.sqrt(np.add.reduceat(var, bins)) / omega
    k = int(np.argmax(prof - 3.0 * sigma))
    below = np.nonzero(prof[k:] + 3.0 * sigma[k:] < 0.5 * (prof[k] - 3.0 * sigma[k]))[0]
    return float(0.5 * (k + below[0])) if below.size else None


def photometry_of(scene: Scene, acc: Accumulator) -> Photometry:
    """Measure the photometry of a session's counts: a grid of C every :data:`C_STEP` deg
    and gamma every 2.5 deg (0.5 deg within three half-widths of a beam narrower than 15
    deg half-width, see :func:`~lumitrace.photometry.grid.default_gammas`). The same
    counts with every light's flux times one factor (a flux-only edit) give the last
    photometry scaled: intensities, fluxes and their errors by the factor, every ratio,
    angle and relative error as it was."""
    last = _LAST[0] if _LAST else None
    if last is not None and last[0] == _light_key(acc):
        k = _common_factor(last[1], [t.flux for t in acc.emitters])
        if k is not None:
            return _scaled(last[2], k, scene.total_flux)
    ph = _measured(scene, acc)
    _LAST[:] = [(_light_key(acc), [t.flux for t in acc.emitters], ph)]
    return ph


#: The last photometry measured: (counts and lights' colours, lights' fluxes, photometry).
_LAST: list[tuple] = []


def _light_key(acc: Accumulator) -> tuple:
    return acc.version, tuple(s[1] for s in acc.light_state())


def _common_factor(before: list[float], now: list[float]) -> float | None:
    """The one factor every light's flux was multiplied by (None: none, or no light)."""
    if len(before) != len(now) or not sum(before) > 0:
        return None
    k = sum(now) / sum(before)
    same = all(abs(b * k - n) <= 1e-12 * max(abs(n), abs(b * k)) for b, n in zip(before, now))
    return k if same and k > 0 else None


def _scaled(ph: Photometry, k: float, lamp_flux: float) -> Photometry:
    grid = replace(ph.grid, candela=ph.grid.candela * k,
                   sigma=None if ph.grid.sigma is None else ph.grid.sigma * k)
    figures = PhotometricFigures(**scaled_figures(ph.figures.as_dict(), k))
    return replace(ph, grid=grid, figures=figures, lamp_flux=lamp_flux)


def _measured(scene: Scene, acc: Accumulator) -> Photometry:
    rings = emitter_rings(acc)
    half_width = beam_half_width(rings)
    grid, halves, choice = _files_grid(scene, acc, default_gammas(half_width))
    fig = figures(acc, grid, halves, C_STEP, rings, half_width)
    return Photometry(grid, fig, luminous_opening(acc), scene.total_flux, choice)


def known_symmetry(scene: Scene) -> tuple[str, bool]:
    """(the symmetry the files start from, whether it is declared): the stage's declared
    ``lumitrace:symmetry``, else the one its geometry shows (none where it shows none)."""
    if scene.declared_symmetry:
        return scene.declared_symmetry, True
    from ..scene.symmetry import geometric_symmetry

    return geometric_symmetry(scene), False


def files_accuracy(scene: Scene, acc: Accumulator, ph: Photometry | None = None
                   ) -> FilesAccuracy:
    """The accuracy of the files :func:`photometry_of` would write from these counts (or
    of ``ph``'s, written already): the same grid (gammas, C step, symmetry), without the
    figures (a few tens of ms: what a session judges its target on); not met while the
    symmetry could still change. None of it where the counts cannot tell their spread
    (fewer than two photons a light)."""
    if not acc.photons or not acc.spread_known:
        return FilesAccuracy(None, None, None)
    if ph is None:
        grid, _, choice = _files_grid(scene, acc,
                                      default_gammas(beam_half_width(emitter_rings(acc))))
    else:
        grid, choice = ph.grid, ph.symmetry
    return replace(grid_accuracy(grid, C_STEP), settled=choice.settled)


#: The files' grids last measured, by counts and lights' fluxes: a session judges the
#: files on the same counts it then writes them from.
_GRIDS: dict[tuple, tuple] = {}


def _files_grid(scene: Scene, acc: Accumulator, gammas: np.ndarray) -> tuple:
    """:func:`~lumitrace.photometry.measured.symmetric_grid` of the files' layout, from
    the scene's :func:`known_symmetry`, made once per counts
    (:attr:`~lumitrace.film.accumulate.Accumulator.version`), fluxes and known symmetry."""
    known, declared = known_symmetry(scene)
    key = (acc.version, tuple(t.flux for t in acc.emitters), tuple(gammas.tolist()), known,
           declared)
    got = _GRIDS.get(key)
    if got is None:
        got = _GRIDS[key] = symmetric_grid(acc, gammas, C_STEP, SYMMETRY_TOLERANCE,
                                           known, declared)
        for old in list(_GRIDS)[:-2]:
            _GRIDS.pop(old, None)
    return got
