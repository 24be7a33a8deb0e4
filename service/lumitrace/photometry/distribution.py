"""The photometric description of a traced result, measured by the virtual goniophotometer:
the C-gamma grid with its standard errors and symmetry, the figures and the luminous
opening, ready for the IES and EULUMDAT writers, the pictures and the sidecar JSON."""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property, partial
from typing import Callable

import numpy as np

from ..film.accumulate import Accumulator
from ..film.goniometer import GAMMA_EDGES, N_GAMMA, cell_solid_angles
from ..scene import Scene
from .grid import CGammaGrid, default_gammas
from .accuracy import FilesAccuracy, grid_accuracy
from .measured import SymmetryChoice, emitter_rings, symmetric_grid
from .opening import LuminousOpening, luminous_opening, opening_of_exits  # noqa: F401
from .quantities import PhotometricFigures, figures, scaled_figures

#: A symmetry the geometry does not show is used where the counts show the departure from
#: it within this (relative RMS, at its 3 sigma upper bound; see
#: :func:`~lumitrace.photometry.measured.departure`).
SYMMETRY_TOLERANCE = 0.01
#: C step (deg) of the published grid.
C_STEP = 5.0
@dataclass(frozen=True)
class Photometry:
    """The photometric description of a result: the published C-gamma grid (reduced to the
    symmetry the counts hold, with standard errors), the figures, the luminous opening, the
    emitters' flux and each symmetry's estimated departure. ``measure`` is the opening, or
    what measures it when first asked for (:attr:`opening`: a live preview never does)."""

    grid: CGammaGrid
    figures: PhotometricFigures
    measure: LuminousOpening | Callable[[], LuminousOpening]
    lamp_flux: float
    symmetry: SymmetryChoice

    @cached_property
    def opening(self) -> LuminousOpening:
        """The luminous opening (:func:`~lumitrace.photometry.opening.luminous_opening`)."""
        return self.measure() if callable(self.measure) else self.measure

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


def photometry_of(scene: Scene, acc: Accumulator, seed: int = 0) -> Photometry:
    """Measure the photometry of a session's counts: a grid of C every :data:`C_STEP` deg
    and gamma every 2.5 deg (0.5 deg within three half-widths of a beam narrower than 15
    deg half-width, see :func:`~lumitrace.photometry.grid.default_gammas`). The same
    counts with every light's flux times one factor (a flux-only edit) give the last
    photometry scaled: intensities, fluxes and their errors by the factor, every ratio,
    angle and relative error as it was. The luminous opening is the stage's declared one,
    or measured from the exits of the run's first photons with ``seed`` (its seed)
    (:func:`~lumitrace.photometry.opening.luminous_opening`)."""
    last = _LAST[0] if _LAST else None
    # the same counts: the same photons through the same parts, hence the same opening
    # (declared the same way)
    if last is not None and last[0] == _light_key(acc) and last[3] == scene.declared_opening \
            and last[4] == seed:
        k = _common_factor(last[1], [t.flux for t in acc.emitters])
        if k is not None:
            return _scaled(last[2], k, scene.total_flux)
    ph = _measured(scene, acc, seed)
    _LAST[:] = [(_light_key(acc), [t.flux for t in acc.emitters], ph, scene.declared_opening,
                 seed)]
    return ph


#: The last photometry measured: (counts and lights' colours, lights' fluxes, photometry,
#: the opening the scene declared, the seed its opening is measured with).
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
    measure = ph.__dict__.get("opening", ph.measure)  # measured already: kept
    return replace(ph, grid=grid, figures=figures, measure=measure, lamp_flux=lamp_flux)


def _measured(scene: Scene, acc: Accumulator, seed: int = 0) -> Photometry:
    rings = emitter_rings(acc)
    half_width = beam_half_width(rings)
    grid, halves, choice = _files_grid(scene, acc, default_gammas(half_width))
    fig = figures(acc, grid, halves, C_STEP, rings, half_width)
    return Photometry(grid, fig, partial(luminous_opening, scene, acc.photons, seed),
                      scene.total_flux, choice)


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
    figures (a few tens of ms: what a session judges its target on). None of it where the
    counts cannot tell their spread (fewer than two photons a light)."""
    if not acc.photons or not acc.spread_known:
        return FilesAccuracy(None, None, None)
    if ph is None:
        grid = _files_grid(scene, acc, default_gammas(beam_half_width(emitter_rings(acc))))[0]
    else:
        grid = ph.grid
    return grid_accuracy(grid, C_STEP)


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
