"""The peak intensity without the bias of a maximum or of a cell's averaging: a local fit of
the top, located by one half of the photons and measured by the other.

The largest cell of a noisy grid is biased up (the maximum of noise) and the mean over a
cell around a maximum is biased down (by the curvature across it): on a flat top the two
need not cancel. Here each half of the photons fits a quadratic surface (in tangent-plane
coordinates, deg) to the goniometer's fine cells within a radius of its own pick of the
top, and takes the fit's stationary point (kept within the radius) as the peak's
direction; the other half's fit there, an unbiased estimate of the intensity at a point
chosen independently of it, is the value (the pick itself, the top cell of the published
grid, where the fit's maximum is not clearly elsewhere). The two halves' values are
averaged. The fit's standard error is the least-squares sandwich with each cell's binomial
variance.

A value measured at a located direction is low by the top's curvature times the
direction's scatter (a Lambertian disc's flat top, located at 100,000 photons, 1% low).
Where the symmetry fixes a pole (rotational, quadrant) and the top falls away from it, the
top is the pole, located without noise (:func:`pole_top`). The measuring fit has even
quartic terms, so a sharp top's departure from a parabola within the radius does not pull
its value down. What is left is the scatter of a top located elsewhere.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..film.accumulate import Accumulator
from ..film.goniometer import (C_STEP, GAMMA_EDGES, GAMMA_STEP, N_C, N_CELLS, N_GAMMA,
                               cell_solid_angles)
from ..table_cache import kept_table

#: Radius (deg) of the fit: this share of the beam's half width (to where it halves), within
#: the bounds below; the widest for a distribution that never halves.
FIT_SHARE = 0.5
FIT_RADIUS_MIN = 1.5
FIT_RADIUS_MAX = 10.0
#: Near a pole, where a C cell spans only 1.25 sin(gamma) deg of arc, the least radius is
#: this many cells across (the wider of a gamma cell and a C cell at the top), no less than
#: two gamma cells: a beam a few degrees wide along the axis is fitted within half its
#: half width, not across all of it.
FIT_CELLS = 2.0
#: Photons (effective: flux^2 / variance) a half must hold within a fit's reach; with fewer,
#: the fit reaches further (to :data:`FIT_RADIUS_MAX`), and without them the cells' split
#: estimate serves.
MIN_FIT_PHOTONS = 400
#: A half moves its pick of the top to its fit's maximum when that lies this many of its
#: standard errors away (Mahalanobis distance), else keeps the pick.
LOCATE_SIGMAS = 2.0
#: The least radius, in cells, of a fit with quartic terms.
QUARTIC_CELLS = 4.0
#: Moves a half makes toward its fit's maximum before it stops.
LOCATE_STEPS = 4
#: The fit that locates the top reaches this many times the measuring fit's radius: a
#: gentle top's slope is resolved over a wider field (a bias of the location's fit costs
#: only the curvature times its square).
LOCATE_RADIUS = 2.0


@dataclass(frozen=True)
class Peak:
    """The peak intensity (cd), its standard error (cd) and direction (C, gamma, deg)."""

    value: float
    error: float
    c: float
    gamma: float


@kept_table
def _cell_directions() -> np.ndarray:
    """Unit vectors of the goniometer cells' centres in the photometric frame (x = C0,
    y = C90, z = up; gamma from nadir), (N_C * N_GAMMA, 3)."""
    c = np.radians((np.arange(N_C) + 0.5) * C_STEP)
    g = np.radians(0.5 * (GAMMA_EDGES[1:] + GAMMA_EDGES[:-1]))
    sg = np.sin(g)
    d = np.stack([np.cos(c)[:, None] * sg[None, :], np.sin(c)[:, None] * sg[None, :],
                  np.broadcast_to(-np.cos(g), (N_C, N_GAMMA))], axis=-1)
    return d.reshape(-1, 3)


@kept_table
def _cell_omegas() -> np.ndarray:
    """Solid angles (sr) of the goniometer cells, flat (read-only, made once)."""
    omega = cell_solid_angles().reshape(-1).copy()
    omega.flags.writeable = False
    return omega


@functools.lru_cache(maxsize=1)
def _gamma_centres() -> np.ndarray:
    return 0.5 * (GAMMA_EDGES[1:] + GAMMA_EDGES[:-1])


def _cells_within(centre: np.ndarray, radius_deg: float) -> np.ndarray:
    """Flat indices (ascending) of the goniometer cells whose centres lie within
    ``radius_deg`` of the unit vector ``centre``: looked for only in the gamma band and the
    C planes that can hold them."""
    gamma = math.degrees(math.acos(max(-1.0, min(1.0, -float(centre[2])))))
    g = np.flatnonzero(np.abs(_gamma_centres() - gamma) <= radius_deg + GAMMA_STEP)
    rows = _planes_within(centre, gamma, radius_deg)
    cells = (rows[:, None] * N_GAMMA + g[None, :]).ravel()
    inside = _cell_directions()[cells] @ centre >= math.cos(math.radians(radius_deg))
    return cells[inside]


def _planes_within(centre: np.ndarray, gamma: float, radius_deg: float) -> np.ndarray:
    """The C planes (ascending) a cap of ``radius_deg`` about ``centre`` (at ``gamma``, deg)
    can reach: a cap clear of both poles spans asin(sin r / sin gamma) either side of its
    own C (a plane's width more kept as margin); one over a pole, every plane."""
    if radius_deg + 1e-6 >= min(gamma, 180.0 - gamma):
        return np.arange(N_C)
    half = math.degrees(math.asin(min(1.0, math.sin(math.radians(radius_deg))
                                      / math.sin(math.radians(gamma))))) + C_STEP
    c = math.degrees(math.atan2(float(centre[1]), float(centre[0])))
    first = math.ceil((c - half) / C_STEP - 0.5)
    last = math.floor((c + half) / C_STEP - 0.5)
    if last - first + 1 >= N_C:
        return np.arange(N_C)
    return np.sort(np.arange(first, last + 1) % N_C)


def _direction(c_deg: float, gamma_deg: float) -> np.ndarray:
    c, g = math.radians(c_deg), math.radians(gamma_deg)
    return np.array([math.cos(c) * math.sin(g), math.sin(c) * math.sin(g), -math.cos(g)])


def _angles(d: np.ndarray) -> tuple[float, float]:
    """(C, gamma) in degrees of a unit vector."""
    gamma = math.degrees(math.acos(max(-1.0, min(1.0, -float(d[2])))))
    c = math.degrees(math.atan2(float(d[1]), float(d[0]))) % 360.0
    return c, gamma


#: Emitters above which a half's cells are summed over the whole sphere at once: a fit
#: reads a few thousand of the 207,360 cells, but each new read loops over the emitters.
LAZY_EMITTERS = 256


class HalfCells:
    """One half's photon flux (lm) and its binomial variance (lm^2) in the goniometer
    cells, read for the cells a fit asks for (each cell summed once, on first read): the
    peak's fits reach a few hundred cells, not the whole sphere."""

    def __init__(self, acc: Accumulator, half: int):
        self._parts = list(acc.emitter_cells(half))
        self._flux = np.zeros(N_CELLS)
        self._var = np.zeros(N_CELLS)
        self._known = np.zeros(N_CELLS, bool)
        if len(self._parts) > LAZY_EMITTERS:
            self._add_all()

    def _add_all(self) -> None:
        """Every cell at once, each emitter's counts added where it has them."""
        for w, total, values, idx in self._parts:
            if idx is None:
                n = values[:N_CELLS].astype(np.float64)
                self._flux += w * n
                self._var += w * w * n * np.maximum(1.0 - n / total, 0.0)
            else:
                keep = idx < N_CELLS
                n = values[keep].astype(np.float64)
                np.add.at(self._flux, idx[keep], w * n)
                np.add.at(self._var, idx[keep], w * w * n * np.maximum(1.0 - n / total, 0.0))
        self._known[:] = True

    def _add(self, cells: np.ndarray) -> None:
        flux, var = np.zeros(cells.size), np.zeros(cells.size)
        for w, total, values, idx in self._parts:
            if idx is None:
                n = values[cells].astype(np.float64)
            else:  # sorted, unique texel indices
                at = np.minimum(np.searchsorted(idx, cells), max(len(idx) - 1, 0))
                n = (np.where(idx[at] == cells, values[at], 0) if len(idx)
                     else np.zeros(cells.size)).astype(np.float64)
            flux += w * n
            var += w * w * n * np.maximum(1.0 - n / total, 0.0)
        self._flux[cells], self._var[cells] = flux, var
        self._known[cells] = True

    def __call__(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(flux, variance) of ``cells`` (flat indices)."""
        new = cells[~self._known[cells]]
        if new.size:
            self._add(new)
        return self._flux[cells], self._var[cells]


def _tangent_basis(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to the unit vector ``p`` and to each other: u = p x a
    (a the x axis, or y where p lies near x) normalised, v = p x u."""
    x, y, z = float(p[0]), float(p[1]), float(p[2])
    ux, uy, uz = (0.0, z, -y) if abs(x) < 0.9 else (-z, 0.0, x)
    n = math.sqrt(ux * ux + uy * uy + uz * uz)
    ux, uy, uz = ux / n, uy / n, uz / n
    return np.array([ux, uy, uz]), np.array([y * uz - z * uy, z * ux - x * uz, x * uy - y * ux])


def local_fit(cells: HalfCells, centre: np.ndarray, radius_deg: float,
              quartic: bool = False) -> tuple[float, float, np.ndarray, np.ndarray] | None:
    """Quadratic fit of the intensity (cd) over the cells within ``radius_deg`` of
    ``centre`` (area-weighted least squares). Returns (value at ``centre``, its standard
    error, the fit's stationary point as a unit vector, within the radius, its Hessian's
    eigenvalues in cd/deg^2, ascending), or None where too few cells hold light.

    ``quartic``: the even quartic terms are fitted too, so that the value at the centre
    of a sharp top is not pulled down by its departure from a parabola (a cos^30 beam's,
    fitted over half its half width, by 0.25%: a beam's level read low puts its crossings
    outward), where the fit reaches :data:`QUARTIC_CELLS` cells (at a pole, fewer rings
    than that cannot tell a quartic from a parabola)."""
    if quartic:  # a cell's size at the centre: the wider of its gamma and its C extent
        sin_gamma = math.sqrt(max(0.0, 1.0 - float(centre[2]) ** 2))
        quartic = radius_deg >= QUARTIC_CELLS * max(GAMMA_STEP, C_STEP * sin_gamma)
    near = _cells_within(centre, radius_deg)
    if near.size < (24 if quartic else 12):
        return None
    flux, var = cells(near)
    total, spread = float(flux.sum()), float(var.sum())
    if spread <= 0 or total * total < MIN_FIT_PHOTONS * spread:
        return None  # too few photons in reach for six parameters
    omega = _cell_omegas()[near]
    # the monomials 1, x, y, x^2, y^2, xy of the gnomonic-like tangent coordinates (deg),
    # one row each: the normal equations below are then two small matrix products
    u, v = _tangent_basis(centre)
    X = np.empty((9 if quartic else 6, near.size))
    X[0] = 1.0
    np.matmul(np.stack([u, v]), _cell_directions()[near].T, out=X[1:3])
    X[1:3] *= 180.0 / math.pi
    np.multiply(X[1], X[1], out=X[3])
    np.multiply(X[2], X[2], out=X[4])
    np.multiply(X[1], X[2], out=X[5])
    if quartic:  # x^4, y^4, x^2 y^2
        np.multiply(X[3], X[3], out=X[6])
        np.multiply(X[4], X[4], out=X[7])
        np.multiply(X[5], X[5], out=X[8])
    # weights are the cells' solid angles (the fit is of cd = flux / omega over the cap):
    # A = X W X^T, the moment X W cd = X flux, the sandwich's middle X W^2 Sigma X^T =
    # X var X^T (the weights' common scale cancels)
    A, B = (X * omega) @ X.T, (X * var) @ X.T
    try:
        Ainv = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return None
    beta = Ainv @ (X @ flux)
    cov = Ainv @ B @ Ainv  # Cov(beta), the least-squares sandwich
    value, error = float(beta[0]), math.sqrt(max(float(cov[0, 0]), 0.0))
    # stationary point of b1 x + b2 y + b3 x^2 + b4 y^2 + b5 x y, where it is a maximum
    H = np.array([[2 * beta[3], beta[5]], [beta[5], 2 * beta[4]]])
    g = -np.array([beta[1], beta[2]])
    # the fit's maximum, where it has one that stands out of the noise in the fit's
    # gradient (a flat or saddle-shaped top, or a maximum within about two of its standard
    # errors of the centre, keeps the centre: a noisy location on a curved top costs the
    # value it measures there)
    top = np.zeros(2)
    if np.all(np.linalg.eigvalsh(H) < 0):
        step = np.linalg.solve(H, g)
        Hinv = np.linalg.inv(H)
        spread = Hinv @ cov[1:3, 1:3] @ Hinv.T
        try:
            significance = float(step @ np.linalg.solve(spread, step))
        except np.linalg.LinAlgError:
            significance = 0.0
        if significance > LOCATE_SIGMAS ** 2:
            r = float(np.hypot(*step))
            top = step * min(1.0, radius_deg / r)
    p = centre + math.radians(top[0]) * u + math.radians(top[1]) * v
    return value, error, p / np.linalg.norm(p), np.linalg.eigvalsh(H)


def locate(cells: HalfCells, start: np.ndarray, radius_deg: float
           ) -> np.ndarray | None:
    """One half's direction of the top: from ``start``, the fit's maximum while it lies
    clearly elsewhere (at most :data:`LOCATE_STEPS` moves, each within the radius)."""
    at = start
    for _ in range(LOCATE_STEPS):
        fit = local_fit(cells, at, radius_deg)
        if fit is None:
            return None if at is start else at
        if float(fit[2] @ at) > math.cos(math.radians(0.01 * radius_deg)):
            break
        at = fit[2]
    return at


def fit_radius(half_width_deg: float | None, gamma_deg: float = 90.0) -> float:
    """The fit's radius (deg) for a beam of half width ``half_width_deg`` (None: no beam)
    whose top lies ``gamma_deg`` from nadir."""
    if half_width_deg is None:
        return FIT_RADIUS_MAX
    cell = max(GAMMA_STEP, C_STEP * abs(math.sin(math.radians(gamma_deg))))
    least = min(FIT_RADIUS_MIN, FIT_CELLS * cell)
    return min(FIT_RADIUS_MAX, max(least, FIT_SHARE * half_width_deg))


#: Symmetries that fix the poles: a single top near a pole is the pole itself (else its
#: mirror images or turns would be tops too).
POLE_FIXING = ("rotational", "quadrant")


def pole_top(cells: HalfCells, pick: tuple[float, float], radius_deg: float,
             symmetry: str) -> np.ndarray | None:
    """The pole near ``pick`` (C, gamma; within ``radius_deg``) where the distribution's
    ``symmetry`` fixes the poles and its top lies there: its fit about the pole falls
    away from it (rotational: the Hessian's trace negative, its eigenvalues being one;
    quadrant: both eigenvalues negative). Such a top is the pole itself, not a place
    located in noise (a located place scatters about the top, and the value measured
    there is low by the curvature times the scatter: 1% for a Lambertian disc at 100,000
    photons). None where the top is elsewhere (a ring about the axis, a saddle)."""
    if symmetry not in POLE_FIXING:
        return None
    for gamma in (0.0, 180.0):
        if abs(pick[1] - gamma) <= radius_deg:
            pole = _direction(0.0, gamma)
            fit = local_fit(cells, pole, radius_deg)
            if fit is None:
                continue
            falls = fit[3].sum() < 0 if symmetry == "rotational" else fit[3][-1] < 0
            if falls:
                return pole
    return None


def fitted_peak(acc: Accumulator, picks: tuple[tuple[float, float], tuple[float, float]],
                half_width_deg: float | None, symmetry: str = "none") -> Peak | None:
    """The peak from the two halves: ``picks`` are each half's (C, gamma) of its top cell;
    each half locates the peak near its own pick and the other half measures it there
    (at a pole where ``symmetry`` fixes it and the top lies there: :func:`pole_top`).
    None where a fit is not possible (too little light near the top)."""
    cells = [HalfCells(acc, h) for h in (0, 1)]
    radius = fit_radius(half_width_deg, max((g for _, g in picks),
                                            key=lambda g: math.sin(math.radians(g))))
    while radius < FIT_RADIUS_MAX and any(
            local_fit(cells[h], _direction(*picks[h]), radius) is None for h in (0, 1)):
        radius = min(FIT_RADIUS_MAX, 2.0 * radius)  # too few photons in reach: reach further
    values, errors, where = [], [], []
    for h in (0, 1):
        located = pole_top(cells[h], picks[h], LOCATE_RADIUS * radius, symmetry)
        if located is None:
            located = locate(cells[h], _direction(*picks[h]), LOCATE_RADIUS * radius)
        if located is None:
            return None
        measured = local_fit(cells[1 - h], located, radius, quartic=True)
        if measured is None:
            return None
        values.append(measured[0])
        errors.append(measured[1])
        where.append(located)
    mid = where[0] + where[1]
    c, gamma = _angles(mid / np.linalg.norm(mid))
    return Peak(0.5 * (values[0] + values[1]), 0.5 * math.hypot(*errors), c, gamma)
