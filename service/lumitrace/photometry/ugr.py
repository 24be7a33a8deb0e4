"""The CIE unified glare rating table (CIE 117:1995, tabular method of CIE 190:2010), with a
standard error for every cell.

The 19 standard rooms (x across the line of sight by y along it, 2H x 2H to 12H x 8H), the
five reflectance sets (ceiling / walls / floor cavity: 70/50/20 .. 30/30/20), luminaires
every 0.25 H (H the height of the luminaire plane above the eye) from S/2 off the walls,
the observer at the middle of a wall looking along y, crosswise (the luminaire's long axis
across the line of sight) and endwise (turned 90 deg). A luminaire's long axis is C90 (the
C0-C180 plane across it, as EULUMDAT has a linear luminaire) unless it is linear along C0
(:func:`~lumitrace.photometry.opening.long_axis`): crosswise then sees it with C90 toward
the observer. The table in the C0 frame:

    UGR = 8 log10(0.25 / Lb * sum L^2 omega / p^2),   L^2 omega = I^2 / (A_p r^2)

with I the intensity toward the eye, A_p the projected luminous area, r the distance, p
Guth's position index from CIE 117 table 4.1 (:mod:`.guth`; the luminaires it gives an
index for: T/R <= 3, gamma <= 85 deg, H/R within the table). The background luminance is
Lb = E_WID / pi, the indirect illuminance of the walls from a three-surface flux transfer
(floor cavity, walls, ceiling; the exact form factor of opposed rectangles), which gives
CIE 190's transfer factors (its table 5) to their rounding. The flux first reaching the
floor is the share of the downward flux landing on it from the room's luminaires (their
positions averaged, the distribution averaged over C), the rest of the downward flux on
the walls, the upward flux on the ceiling. Errors: the grid's standard errors propagated
to first order (each value the grid holds independent, its mirror images and the poles'
shared values moving together): UGR is a smooth function of the grid, and at the errors a
result carries its second-order terms are far below the first (a bootstrap of 400
redraws agrees, ``tests/photometry/test_ugr.py``); a measured opening's errors are added
in quadrature. UGR does not depend on H; H = 2 m.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from ..table_cache import kept_table
from .grid import CGammaGrid, default_gammas
from .guth import table_index
from .luminance import projected_area, taps

#: Standard rooms: (x, y) in multiples of H, x across the line of sight.
ROOMS = ((2, 2), (2, 3), (2, 4), (2, 6), (2, 8), (2, 12), (4, 2), (4, 3), (4, 4), (4, 6),
         (4, 8), (4, 12), (8, 4), (8, 6), (8, 8), (8, 12), (12, 4), (12, 6), (12, 8))
#: Reflectances (ceiling, walls, floor cavity).
REFLECTANCES = ((0.7, 0.5, 0.2), (0.7, 0.3, 0.2), (0.5, 0.5, 0.2), (0.5, 0.3, 0.2),
                (0.3, 0.3, 0.2))
REFLECTANCE_NAMES = tuple("/".join(f"{round(100 * r)}" for r in refl) for refl in REFLECTANCES)
#: Luminaire spacing (multiples of H) and the height H (m).
SPACING = 0.25
HEIGHT = 2.0
#: The catalogue value's room and reflectances.
CATALOGUE_ROOM, CATALOGUE_REFLECTANCE = (4, 8), 0


def counted(t: np.ndarray, r: np.ndarray, h: float) -> np.ndarray:
    """Which luminaires (T across, R along the line of sight, H above the eye) the sum
    takes: those CIE 117 table 4.1 gives a position index for (T/R <= 3, H/R <= 1.7, or
    H/R <= 1.8 from T/R 0.4, or H/R <= 1.9 from T/R 0.9) below gamma 85 deg."""
    tr, hr = np.abs(t) / r, h / r
    gamma = np.degrees(np.arctan2(np.hypot(t, r), h))
    domain = (hr <= 1.7 + 1e-9) | ((hr <= 1.8 + 1e-9) & (tr >= 0.4 - 1e-9)) | \
        ((hr <= 1.9 + 1e-9) & (tr >= 0.9 - 1e-9))
    return (tr <= 3.0 + 1e-9) & (gamma <= 85.0 + 1e-9) & domain


@dataclass(frozen=True)
class Room:
    """One standard room's luminaires that count: positions T (across), R (along the line
    of sight) (m), their distance to the eye (m), gamma and C toward the eye (deg,
    crosswise and endwise) and position index; and the room's luminaire count."""

    x: float
    y: float
    n: int
    t: np.ndarray
    r: np.ndarray
    distance: np.ndarray
    gamma: np.ndarray
    c_crosswise: np.ndarray
    c_endwise: np.ndarray
    p: np.ndarray


@lru_cache(maxsize=32)
def room(x: float, y: float, spacing: float = SPACING, h: float = HEIGHT) -> Room:
    """The geometry of the room x H across by y H along the line of sight."""
    s = spacing * h
    n_t, n_r = int(round(x / spacing)), int(round(y / spacing))
    ts = (np.arange(n_t) + 0.5) * s - 0.5 * n_t * s
    rs = (np.arange(n_r) + 0.5) * s
    t, r = (a.ravel() for a in np.meshgrid(ts, rs))
    keep = counted(t, r, h)
    t, r = t[keep], r[keep]
    # crosswise: C0 points back at the observer (-y), C90 along +x; endwise: C0 along +x,
    # C90 along +y; the eye lies at (-t, -r) horizontally from a luminaire
    cross = np.degrees(np.arctan2(-t, r)) % 360.0
    end = np.degrees(np.arctan2(-r, -t)) % 360.0
    return Room(x, y, n_t * n_r, t, r, np.sqrt(t * t + r * r + h * h),
                np.degrees(np.arctan2(np.hypot(t, r), h)), cross, end, table_index(t, r, h))


def _parallel_form_factor(a: float, b: float, c: float) -> float:
    """Form factor between directly opposed parallel rectangles a x b, c apart."""
    x, y = a / c, b / c
    return float(2.0 / (np.pi * x * y) * (
        0.5 * np.log((1 + x * x) * (1 + y * y) / (1 + x * x + y * y))
        + x * np.sqrt(1 + y * y) * np.arctan(x / np.sqrt(1 + y * y))
        + y * np.sqrt(1 + x * x) * np.arctan(y / np.sqrt(1 + x * x))
        - x * np.arctan(x) - y * np.arctan(y)))


def transfer_factors(x: float, y: float, reflectance) -> np.ndarray:
    """The walls' indirect illuminance, per unit of initial flux on (floor, walls,
    ceiling) spread over the walls' area: CIE 190's F_T (FW, WW - 1, CW), from the flux
    transfer between the three surfaces of the room x H by y H, H high."""
    rc, rw, rf = reflectance
    area_f, area_w = float(x * y), 2.0 * (x + y)
    f_fc = _parallel_form_factor(x, y, 1.0)
    f_wf = (1.0 - f_fc) * area_f / area_w
    form = np.array([[0.0, 1.0 - f_fc, f_fc], [f_wf, 1.0 - 2.0 * f_wf, f_wf],
                     [f_fc, 1.0 - f_fc, 0.0]])  # from floor, walls, ceiling to each
    rho = np.array([rf, rw, rc])
    total = np.linalg.inv(np.eye(3) - form * rho[None, :])  # E = total @ E0
    areas = np.array([area_f, area_w, area_f])
    # first-reflection illuminance of the walls from unit flux on each surface, onward
    return (total[1] - np.eye(3)[1]) / areas * area_w


def _floor_share(gamma_deg: np.ndarray, x: float, y: float) -> np.ndarray:
    """Share of the flux leaving at ``gamma`` (deg, below 90) that lands on the floor
    cavity plane H below, averaged over C and over luminaire positions in the room (each
    axis: 1 - |offset| / side)."""
    phi = np.radians(np.arange(0.0, 360.0, 5.0) + 2.5)
    d = np.tan(np.radians(np.minimum(gamma_deg, 89.999)))[:, None]
    fx = np.clip(1.0 - np.abs(d * np.cos(phi)) / x, 0.0, None)
    fy = np.clip(1.0 - np.abs(d * np.sin(phi)) / y, 0.0, None)
    return (fx * fy).mean(axis=1)


@dataclass(frozen=True)
class UgrTable:
    """UGR (19 rooms by 5 reflectances, crosswise and endwise) with standard errors."""

    crosswise: np.ndarray
    endwise: np.ndarray
    crosswise_error: np.ndarray
    endwise_error: np.ndarray
    #: the axis a linear luminaire is long along ("C0", "C90"; "": not linear, crosswise
    #: has C90 across the line of sight)
    long_axis: str = ""

    def catalogue(self, endwise: bool = False) -> tuple[float, float]:
        """(UGR, error) for 4H x 8H, 70/50/20."""
        i, j = ROOMS.index(CATALOGUE_ROOM), CATALOGUE_REFLECTANCE
        if endwise:
            return float(self.endwise[i, j]), float(self.endwise_error[i, j])
        return float(self.crosswise[i, j]), float(self.crosswise_error[i, j])

    def as_dict(self) -> dict:
        """The record's fields."""
        cu, ce = self.catalogue()
        eu, ee = self.catalogue(endwise=True)
        return {"ugr_table": {"rooms_h": [list(r) for r in ROOMS],
                              "reflectances": list(REFLECTANCE_NAMES), "spacing_h": SPACING,
                              "crosswise": _rows(self.crosswise),
                              "endwise": _rows(self.endwise),
                              "crosswise_error": _rows(self.crosswise_error),
                              "endwise_error": _rows(self.endwise_error),
                              "long_axis": self.long_axis,
                              "crosswise_is": f"the luminaire's {self.long_axis or 'C90'} axis "
                                              "across the line of sight"},
                "ugr_4h8h_70_50_20": cu, "ugr_4h8h_70_50_20_error": ce,
                "ugr_4h8h_70_50_20_endwise": eu, "ugr_4h8h_70_50_20_endwise_error": ee}


def _rows(a: np.ndarray) -> list:
    return [[round(float(v), 4) if np.isfinite(v) else None for v in row] for row in a]


class _Model:
    """The table as a function of the full grid's values (flattened): the taps of every
    room's luminaires and the linear maps to the background luminances, fixed by the grid's
    layout; the luminaires' weights, by the luminous opening (:meth:`of`)."""

    def __init__(self, tables: tuple):
        """``tables``: :func:`_layout_tables` of the grid's layout."""
        (self.shape, self.idx, self.w, self._c, self._gamma, self._d2, self._p2, self.starts,
         self.lb) = tables
        self.weight = np.empty(0)
        self._last: tuple | None = None  # (opening, its weights)

    def of(self, opening) -> _Model:
        """A copy of this model with the weights (1 / (projected area d^2 p^2)) of
        ``opening`` (this one stays as it is: threads may share it)."""
        last = self._last
        if last is None or last[0] != opening:
            last = self._last = (opening, 1.0 / (projected_area(opening, self._c, self._gamma)
                                                 * self._d2 * self._p2))
        view = copy.copy(self)
        view.weight = last[1]
        return view

    def evaluate(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(crosswise, endwise) UGR, each (draws, rooms, reflectances), of grid values
        (draws, cells)."""
        s, back = self._sums(np.ascontiguousarray(values.T))
        with np.errstate(divide="ignore", invalid="ignore"):
            u = 8.0 * np.log10(0.25 * s.reshape(len(ROOMS), 2, 1, -1) / back[:, None])
        u = np.moveaxis(u, -1, 0)  # (draws, rooms, orientations, reflectances)
        return u[:, :, 0], u[:, :, 1]

    def _sums(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the glare sums (sums, draws), the background luminances (rooms, reflectances,
        draws)) of grid values (cells, draws)."""
        i = np.einsum("pk,pkd->pd", self.w, cells[self.idx])  # one gather per tap
        s = np.add.reduceat(i * i * self.weight[:, None], self.starts, axis=0)
        rings = cells.reshape(self.shape + (-1,)).sum(axis=0)  # (gammas, draws)
        return s, np.einsum("rfg,gd->rfd", self.lb, rings)

    def gradient(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The derivatives by the full grid's values (cells,) at ``values`` of 8 log10 of
        the glare sums (sums, planes, gammas) and of the background luminances (rooms,
        reflectances, gammas; the same for every plane): UGR's is their difference."""
        cells = values[:, None]
        s, back = self._sums(cells)
        i = np.einsum("pk,pk->p", self.w, cells[self.idx][..., 0])
        row = np.repeat(np.arange(len(self.starts)), np.diff(np.r_[self.starts, len(i)]))
        coef = (2.0 * i * self.weight)[:, None] * self.w  # d(sum) / d(cell) per tap
        n = int(np.prod(self.shape))
        d_s = np.bincount((row[:, None] * n + self.idx).ravel(), weights=coef.ravel(),
                          minlength=len(self.starts) * n).reshape(len(self.starts), *self.shape)
        scale = 8.0 / math.log(10.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            return scale * d_s / s[:, 0, None, None], scale * self.lb / back[..., 0, None]


def ugr_table(grid: CGammaGrid, opening) -> UgrTable:
    """The UGR table of ``grid`` (cd, with sigma) with luminous area ``opening`` (a
    :class:`~lumitrace.photometry.distribution.LuminousOpening`), its errors propagated
    from the grid's."""
    model = _model(grid, opening)
    full = grid.full()
    values = full.candela.reshape(1, -1)
    cross, end = model.evaluate(values)
    err = _propagated(grid, *model.gradient(full.candela.ravel()))
    # the measured opening's own errors (each dimension's), added in quadrature
    for name, e in zip(("length", "width", "height"), getattr(opening, "error", ())):
        if e:
            moved = _model(grid, replace(opening, **{name: getattr(opening, name) + e}))
            c2, e2 = moved.evaluate(values)
            err = np.sqrt(err ** 2 + np.stack([c2[0] - cross[0], e2[0] - end[0]], axis=1) ** 2)
    bad = ~np.isfinite(np.stack([cross[0], end[0]], axis=1)) | ~np.isfinite(err)
    err = np.where(bad, np.nan, err)
    (c, ce), (e, ee) = _named(opening, (cross[0], err[:, 0]), (end[0], err[:, 1]))
    from .opening import long_axis

    return UgrTable(c, e, ce, ee, long_axis(opening))


def _propagated(grid: CGammaGrid, d_glare: np.ndarray, d_back: np.ndarray) -> np.ndarray:
    """Standard errors (rooms, orientations, reflectances) of UGR = glare - background,
    given their derivatives by the full grid's values (:meth:`_Model.gradient`), from the
    published grid's errors: each value it holds is independent, every plane it stands for
    moves with it, and each pole is one value."""
    unfold = _unfold_index(grid)
    planes = len(grid.c)
    fold = np.zeros((planes, len(unfold)))
    fold[unfold, np.arange(len(unfold))] = 1.0
    glare = np.einsum("mc,scg->smg", fold, d_glare)  # (sums, published planes, gammas)
    back = fold.sum(axis=1)[:, None] * d_back[:, :, None, :]  # (rooms, refl., planes, g)
    d = glare.reshape(len(ROOMS), 2, 1, planes, -1) - back[:, None]
    sigma = np.asarray(grid.sigma, np.float64)
    with np.errstate(invalid="ignore"):
        body = np.einsum("rofmg,mg->rof", d[..., 1:-1] ** 2, sigma[:, 1:-1] ** 2)
        poles = sum((d[..., j].sum(axis=-1) * sigma[0, j]) ** 2 for j in (0, -1))
    return np.sqrt(body + poles)


def _named(opening, cross, end):
    """(crosswise, endwise) named from the luminaire's long axis: the tables computed with
    C90 across the line of sight come first, unless the luminaire is long along C0."""
    from .opening import long_axis

    return (end, cross) if long_axis(opening) == "C0" else (cross, end)


def _layout_tables(c: tuple[float, ...], gamma: tuple[float, ...], symmetry: str) -> tuple:
    """What a UGR table takes from a grid's layout (C planes and gammas, deg; symmetry):
    the full grid's shape, the taps (indices, weights) of every room's luminaires, their
    directions (C, gamma, deg), distances and position indices squared, each sum's first
    row, and the background luminances per unit intensity of each gamma (rooms,
    reflectances, gammas)."""
    grid = CGammaGrid(np.array(c), np.array(gamma), np.zeros((len(c), len(gamma))), symmetry)
    full = grid.full()
    shape = full.candela.shape
    gam = full.gamma
    edges = np.concatenate([[0.0], 0.5 * (gam[1:] + gam[:-1]), [180.0]])
    cos_e = np.cos(np.radians(edges))
    dc = np.radians(360.0 / shape[0])
    down_cos = np.clip(cos_e, 0.0, None)
    omega_down = (down_cos[:-1] - down_cos[1:]) * dc  # each zone's part below 90
    omega_up = (cos_e[:-1] - cos_e[1:]) * dc - omega_down
    idx, w, seen, lbs = [], [], [], []
    for x, y in ROOMS:
        g = room(float(x), float(y))
        for c in (g.c_crosswise, g.c_endwise):
            i, wi = taps(grid, c, g.gamma)
            idx.append(i)
            w.append(wi)
            seen.append((np.broadcast_to(c, g.gamma.shape), g.gamma,
                         np.broadcast_to(g.distance ** 2, g.gamma.shape),
                         np.broadcast_to(g.p ** 2, g.gamma.shape)))
        floor = omega_down * _floor_share(gam, x, y)
        # flux (lm) to floor, walls, ceiling per unit intensity of each gamma (all C)
        to = np.stack([floor, omega_down - floor, omega_up])
        a_w = 2.0 * HEIGHT * HEIGHT * (x + y)
        lbs.append(np.stack([g.n / a_w * transfer_factors(x, y, refl) @ to / np.pi
                             for refl in REFLECTANCES]))  # (reflectances, gammas)
    idx, w = np.concatenate(idx), np.concatenate(w)
    # each luminaire's direction (C, gamma) as the observer sees it, its distance and
    # position index squared: what its weight takes from the room
    c_, gamma_, d2, p2 = (np.concatenate(a) for a in zip(*seen))
    # (not a matrix product: BLAS's threads would spin beside the tracing threads)
    starts = np.cumsum([0] + [len(a) for a, *_ in seen[:-1]])
    lb = np.stack(lbs)
    return shape, idx, w, c_, gamma_, d2, p2, starts, lb


#: The same tables kept on disk, for the layouts every run uses (the default gammas); a
#: narrow beam's own gammas follow its measured width, so they are made in the process.
_kept_layout_tables = kept_table(_layout_tables)


#: The last models made, by grid layout: a service writes the same luminaire's table again
#: and again.
_MODELS: dict[tuple, _Model] = {}
#: The gammas of a grid that no narrow beam refines.
DEFAULT_GAMMAS = default_gammas()


def _model(grid: CGammaGrid, opening) -> _Model:
    """The table's model of a grid's layout (C planes, gammas, symmetry), with the weights
    of ``opening`` (measured from the photons, it differs a little from write to write)."""
    key = (tuple(grid.c.tolist()), tuple(grid.gamma.tolist()), grid.symmetry)
    model = _MODELS.get(key)
    if model is None:
        make = _kept_layout_tables if np.array_equal(grid.gamma, DEFAULT_GAMMAS) \
            else _layout_tables
        model = _MODELS[key] = _Model(make(*key))
        for old in list(_MODELS)[:-8]:
            _MODELS.pop(old, None)
    return model.of(opening)


def _unfold_index(grid: CGammaGrid) -> np.ndarray:
    """For every plane of ``grid.full()``, the plane of ``grid`` it repeats."""
    planes = np.arange(len(grid.c), dtype=np.float64)[:, None] * np.ones((1, len(grid.gamma)))
    cs = np.arange(0.0, 360.0 - 1e-9, _step(grid))
    return np.rint(grid.at(cs, planes)[:, 0]).astype(np.int64)


def _step(grid: CGammaGrid) -> float:
    d = np.diff(grid.c)
    return float(d.min()) if d.size else 5.0


# -- CIE 190: the observer's position, the lamp flux ------------------------------------

#: Luminaire spacings (multiples of H) CIE 190 states the variation of the observer
#: position for, and the room and reflectances (ceiling / walls / floor cavity) it is
#: stated in: the catalogue's.
VARIATION_SPACINGS = (1.0, 1.5, 2.0)
VARIATION_ROOM, VARIATION_REFLECTANCE = CATALOGUE_ROOM, CATALOGUE_REFLECTANCE
#: Positions of the observer along the wall, in steps of this fraction of the spacing
#: (one period of the layout).
VARIATION_STEPS = 16
#: Redraws of the grid within its errors that give the variation's standard errors.
VARIATION_DRAWS = 64


@dataclass(frozen=True)
class ObserverVariation:
    """How far UGR moves from the table's value (spacing 0.25 H) when the luminaires of
    the catalogue room (4H x 8H, 70/50/20) stand ``spacings`` H apart (rows from S/2 off
    the observer's wall, as the table's) and the observer stands anywhere along that wall
    against their columns: (largest rise, largest fall) per spacing, crosswise and endwise,
    with standard errors."""

    spacings: tuple[float, ...]
    crosswise: np.ndarray        # (spacings, 2): + rise, - fall
    endwise: np.ndarray
    crosswise_error: np.ndarray
    endwise_error: np.ndarray

    def as_dict(self) -> dict:
        r = lambda a: [[round(float(v), 4) if np.isfinite(v) else None for v in row]  # noqa
                       for row in a]
        return {"ugr_observer_variation": {
            "room_h": list(VARIATION_ROOM),
            "reflectances": REFLECTANCE_NAMES[VARIATION_REFLECTANCE],
            "spacing_h": list(self.spacings), "crosswise": r(self.crosswise),
            "endwise": r(self.endwise), "crosswise_error": r(self.crosswise_error),
            "endwise_error": r(self.endwise_error)}}


def _layout(spacing: float, across: float, along: float, x: float, y: float,
            h: float = HEIGHT) -> tuple[np.ndarray, np.ndarray]:
    """(T, R) (m) of the luminaires of a room x H by y H on a square grid ``spacing`` H
    apart, shifted ``across`` and ``along`` (fractions of the spacing; 0.5 and 0.5: the
    table's layout, centred across, rows from S/2) against the observer at the middle of
    its wall; those the glare sum takes (:func:`counted`)."""
    s = spacing * h
    t = -0.5 * x * h + (np.arange(int(math.ceil(x / spacing)) + 1) + across) * s
    r = (np.arange(int(math.ceil(y / spacing)) + 1) + along) * s
    t = t[(t > -0.5 * x * h) & (t < 0.5 * x * h)]
    r = r[(r > 0.0) & (r < y * h)]
    t, r = (a.ravel() for a in np.meshgrid(t, r))
    keep = counted(t, r, h)
    return t[keep], r[keep]


def _sums(values: np.ndarray, grid: CGammaGrid, opening, t: np.ndarray, r: np.ndarray,
          h: float = HEIGHT) -> np.ndarray:
    """The glare sums sum I^2 / (A_p d^2 p^2), crosswise and endwise, of luminaires at
    (T, R) for grid values ``values`` (draws, full cells): (draws, 2)."""
    gamma = np.degrees(np.arctan2(np.hypot(t, r), h))
    d2, p2 = t * t + r * r + h * h, table_index(t, r, h) ** 2
    out = []
    for c in (np.degrees(np.arctan2(-t, r)) % 360.0, np.degrees(np.arctan2(-r, -t)) % 360.0):
        idx, w = taps(grid, c, gamma)
        i = np.einsum("pk,dpk->dp", w, values[:, idx])
        weight = 1.0 / (projected_area(opening, c, gamma) * d2 * p2)
        out.append((i * i * weight).sum(axis=1))
    return np.stack(out, axis=1)


def observer_variation(grid: CGammaGrid, opening, spacings=VARIATION_SPACINGS,
                       seed: int = 0) -> ObserverVariation:
    """CIE 190's variation of the observer position (see :class:`ObserverVariation`).

    For each spacing S the luminaires fill the room on a square grid S apart, its rows
    S/2, 3S/2, ... from the observer's wall, its columns' phase against the observer
    stepped over one period (:data:`VARIATION_STEPS`), the background luminance that of the
    table's room with the same luminaires per area (the same installation; it does not
    depend on where the observer stands). The errors: the spread of the rise and fall over
    :data:`VARIATION_DRAWS` redraws of the grid within its errors, the table's value
    redrawn with them."""
    from .grid import redrawn

    full = grid.full()
    model = _model(grid, opening)
    unfold = _unfold_index(grid)
    draws = redrawn(grid, np.random.default_rng(seed), VARIATION_DRAWS)[:, unfold]
    values = np.concatenate([full.candela.reshape(1, -1), draws.reshape(VARIATION_DRAWS, -1)])
    cross, end = model.evaluate(values)
    room_i = ROOMS.index(VARIATION_ROOM)
    table = np.stack([cross[:, room_i, VARIATION_REFLECTANCE],
                      end[:, room_i, VARIATION_REFLECTANCE]], axis=1)  # (draws, 2)
    rings = values.reshape((len(values),) + full.candela.shape).sum(axis=1)
    lb_table = rings @ model.lb[room_i, VARIATION_REFLECTANCE]  # (draws,)
    x, y = VARIATION_ROOM
    steps = np.arange(VARIATION_STEPS) / VARIATION_STEPS
    rise, fall = [], []
    for s in spacings:
        lb = lb_table * (SPACING / s) ** 2  # the same luminaires per area
        shifted = []
        for across in steps:
            t, r = _layout(s, across, 0.5, x, y)
            with np.errstate(divide="ignore", invalid="ignore"):
                sums = _sums(values, grid, opening, t, r)
                shifted.append(8.0 * np.log10(0.25 * sums / lb[:, None]) - table)
        shifted = np.stack(shifted)  # (positions, draws, 2)
        rise.append(np.nanmax(shifted, axis=0))
        fall.append(np.nanmin(shifted, axis=0))
    rise, fall = np.stack(rise, axis=1), np.stack(fall, axis=1)  # (draws, spacings, 2)
    value = np.stack([rise[0], fall[0]], axis=-1)  # (spacings, 2 orientations, 2)
    error = np.stack([rise[1:].std(axis=0, ddof=1), fall[1:].std(axis=0, ddof=1)], axis=-1)
    (c, ce), (e, ee) = _named(opening, (value[:, 0], error[:, 0]), (value[:, 1], error[:, 1]))
    return ObserverVariation(tuple(spacings), c, e, ce, ee)


def position_ugr(grid: CGammaGrid, opening, spacing: float, across: float = 0.5
                 ) -> tuple[float, float]:
    """(crosswise, endwise) UGR of the catalogue room, 70/50/20, with luminaires ``spacing``
    H apart, the observer at ``across`` of a spacing against their columns (0.5: the
    table's own layout, centred), named from the long axis as the table is."""
    model = _model(grid, opening)
    values = grid.full().candela.reshape(1, -1)
    room_i = ROOMS.index(VARIATION_ROOM)
    rings = values.reshape((1,) + grid.full().candela.shape).sum(axis=1)
    lb = (rings @ model.lb[room_i, VARIATION_REFLECTANCE]) * (SPACING / spacing) ** 2
    t, r = _layout(spacing, across, 0.5, *VARIATION_ROOM)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = 8.0 * np.log10(0.25 * _sums(values, grid, opening, t, r)[0] / lb[0])
    (c, _), (e, _) = _named(opening, (float(u[0]), 0.0), (float(u[1]), 0.0))
    return c, e


def flux_correction(lamp_flux: float, other: float) -> float:
    """What UGR gains when the table's lamps (``lamp_flux`` lm) are replaced by lamps of
    ``other`` lm with the same distribution: 8 log10(other / lamp_flux) (every luminance,
    and the background, scales with the flux)."""
    return 8.0 * math.log10(other / lamp_flux)


def flux_fields(lamp_flux: float) -> dict:
    """The record's fields on the lamp flux the table refers to and the correction term."""
    return {"ugr_lamp_flux": float(lamp_flux),
            "ugr_flux_correction": "8 log10(flux / ugr_lamp_flux), added to every value of "
                                   "the table and its observer variation's reference, for "
                                   "lamps of another flux with the same distribution",
            "ugr_flux_corrections": {f"{k:g}": round(flux_correction(1.0, k), 4)
                                     for k in (0.5, 0.8, 1.25, 2.0)}}
