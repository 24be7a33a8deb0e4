"""Photometry measured by the virtual goniophotometer: intensities (cd) on a C-gamma grid with
their standard errors, symmetry judged against the counts' own noise, and symmetry averaging
done on the counts.

A grid value is the photon flux through its cell (C +- half the C step, gamma between the
midpoints to its neighbours) over the cell's solid angle: an unbiased estimate of the mean
intensity over the cell, with the exact binomial variance of analog photons. The poles,
gamma 0 and 180, are directions, not planes: their value, the same in every plane, is the
mean over the whole polar cap (all C), from the pole to the midpoint to the next gamma or,
where the pole is lit (at least :data:`LIT_SHARE` of the grid's largest value) and that cap
is noisier than :data:`POLE_NOISE` times the median relative error of the grid's other lit
values, as far as it takes to be no noisier than that (0.5 deg steps, at most
:data:`POLE_CAP_MAX` deg). With planes every 15 deg all round the first cap already holds 3
times a neighbouring cell's solid angle; a rotationally symmetric grid, whose other cells
are whole rings, needs a wider one (the Lambertian disc's: about 6 deg). Nothing is
interpolated or filtered, so the files carry no bias the stated errors do not cover, beyond
the averaging over each cell (second order in the cell size where the distribution is
smooth; at a kink, such as the horizon of a one-sided disc, the cell's mean).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from ..errors import LumitraceError
from ..film.accumulate import Accumulator
from ..film.goniometer import C_STEP, GAMMA_EDGES, N_C, N_CELLS, N_GAMMA, cell_solid_angles
from .grid import CGammaGrid

#: Symmetries tried, strongest first.
CANDIDATES = ("rotational", "quadrant", "C0-C180", "C90-C270")
#: A value is lit at this share of the grid's largest value (the field angle's level).
LIT_SHARE = 0.1
#: A lit pole's relative error may be this many times the median of the other lit values'.
POLE_NOISE = 1.5
#: The widest polar cap (deg from the pole), and the steps it widens in (deg).
POLE_CAP_MAX = 7.5
POLE_CAP_STEP = 0.5


def _plane_of_bin(c_step: float) -> tuple[np.ndarray, int]:
    """The C plane (0 .. planes - 1) each goniometer C bin belongs to, and the planes."""
    planes = 360.0 / c_step
    if abs(planes - round(planes)) > 1e-9 or abs(c_step / (2 * C_STEP) - round(
            c_step / (2 * C_STEP))) > 1e-9 or round(planes) % 4:
        raise LumitraceError(f"a C step of {c_step:g} deg is not a multiple of "
                             f"{2 * C_STEP:g} deg dividing 90 deg")
    n = int(round(planes))
    centres = (np.arange(N_C) + 0.5) * C_STEP
    return (np.floor((centres + 0.5 * c_step) / c_step).astype(np.int64) % n), n


def _zone_of_bin(gammas: np.ndarray) -> np.ndarray:
    """The grid gamma (index) each goniometer gamma bin belongs to: the zone between the
    midpoints to its neighbours (0 and 180 deg at the ends)."""
    g = np.asarray(gammas, np.float64)
    if g[0] != 0.0 or g[-1] != 180.0 or np.any(np.diff(g) <= 0):
        raise LumitraceError("grid gammas must rise from 0 to 180 deg")
    edges = np.concatenate([[0.0], 0.5 * (g[1:] + g[:-1]), [180.0]])
    pos = np.searchsorted(GAMMA_EDGES, edges)
    pos = np.clip(pos, 0, len(GAMMA_EDGES) - 1)
    if not np.allclose(GAMMA_EDGES[pos], edges, atol=1e-9):
        raise LumitraceError("grid gammas must lie on a 0.5 deg raster")
    centres = 0.5 * (GAMMA_EDGES[1:] + GAMMA_EDGES[:-1])
    return np.searchsorted(edges, centres) - 1


def planes_kept(symmetry: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(for every plane 0 .. n - 1, the kept plane it is averaged into; kept planes in C
    order) for a symmetry of type C photometry with ``n`` planes all round."""
    i = np.arange(n)
    if symmetry == "none":
        return i, i
    if symmetry == "rotational":
        return np.zeros(n, np.int64), np.array([0])
    c0 = np.where(i <= n // 2, i, n - i)  # folded about the C0-C180 plane
    if symmetry == "C0-C180":
        return c0, np.arange(n // 2 + 1)
    if symmetry == "quadrant":
        return np.where(c0 <= n // 4, c0, n // 2 - c0), np.arange(n // 4 + 1)
    if symmetry == "C90-C270":
        rep = np.where((i >= n // 4) & (i <= 3 * n // 4), i, (n // 2 - i) % n)
        return rep, np.arange(n // 4, 3 * n // 4 + 1)
    if symmetry == "octant":  # quadrant, and C alike with 90 - C: planes 0 .. 45 deg
        if n % 8:
            raise ValueError(f"{n} planes do not fold into octants")
        quad = np.where(c0 <= n // 4, c0, n // 2 - c0)
        return np.where(quad <= n // 8, quad, n // 4 - quad), np.arange(n // 8 + 1)
    raise ValueError(f"unknown symmetry {symmetry!r}")


@functools.lru_cache(maxsize=16)
def _blocks(c_step: float, gammas: tuple[float, ...]) -> tuple[int, int, np.ndarray, np.ndarray]:
    """How goniometer cells add into grid cells: (planes, C bins per plane, the first gamma
    bin of every grid zone, the grid cells' solid angles (planes, zones))."""
    plane, n = _plane_of_bin(c_step)
    zone = _zone_of_bin(np.array(gammas))
    starts = np.flatnonzero(np.r_[True, zone[1:] != zone[:-1]])
    per = N_C // n
    omega = _add_blocks(cell_solid_angles(), n, per, starts)
    return n, per, starts, omega


def _add_blocks(a: np.ndarray, n: int, per: int, starts: np.ndarray) -> np.ndarray:
    """Sums of fine cells ``a`` (N_C, N_GAMMA) over each plane's C bins (plane 0 holds the
    bins either side of C = 0) and each zone's gamma bins: (planes, zones)."""
    a = np.roll(a, per // 2, axis=0).reshape(n, per, a.shape[1]).sum(axis=1)
    return np.add.reduceat(a, starts, axis=1)


def grid_counts(values: np.ndarray, idx: np.ndarray | None, c_step: float,
                gammas: np.ndarray) -> np.ndarray:
    """An emitter's goniometer counts (dense, or at bins ``idx``) summed into the cells of
    the grid with planes every ``c_step`` and ``gammas``: (planes, zones) float64."""
    n, per, starts, _ = _blocks(float(c_step), tuple(map(float, gammas)))
    if idx is None:
        fine = values[:N_CELLS].reshape(N_C, N_GAMMA)  # integer sums: exact
        return _add_blocks(fine, n, per, starts).astype(np.float64)
    keep = idx < N_CELLS
    ci, gi = np.divmod(idx[keep], N_GAMMA)
    p = ((ci + per // 2) % N_C) // per
    z = np.searchsorted(starts, gi, side="right") - 1
    return np.bincount(p * len(starts) + z, weights=values[keep].astype(np.float64),
                       minlength=n * len(starts)).reshape(n, len(starts))


def ring_counts(values: np.ndarray, idx: np.ndarray | None) -> np.ndarray:
    """An emitter's goniometer counts summed over C: one per gamma bin, (N_GAMMA,)."""
    if idx is None:
        return values[:N_CELLS].astype(np.float64).reshape(N_C, N_GAMMA).sum(axis=0)
    keep = idx < N_CELLS
    return np.bincount(idx[keep] % N_GAMMA, weights=values[keep].astype(np.float64),
                       minlength=N_GAMMA)


#: The grids :func:`measure_all` returns: every symmetry, from all photons and each half.
SYMMETRY_NAMES = ("none", *CANDIDATES)
HALVES = (None, 0, 1)


def emitter_rings(acc: Accumulator) -> list[tuple[float, float, np.ndarray]]:
    """Per emitter with photons: (photon flux (lm), photons, its counts summed over C per
    gamma bin): what the zone fluxes and the beam's width need, made once."""
    return [(w, total, ring_counts(values, idx))
            for w, total, values, idx in acc.emitter_cells()]


def measure_all(acc: Accumulator, gammas: np.ndarray, c_step: float = 5.0,
                symmetries: tuple[str, ...] = SYMMETRY_NAMES
                ) -> dict[tuple[str, int | None], CGammaGrid]:
    """The goniophotometer's C-gamma grids (cd) with standard errors (``sigma``, cd), keyed
    by (symmetry, half): planes every ``c_step`` deg (averaged over the mirror images the
    symmetry names, on the counts), gammas ``gammas`` (deg, 0 .. 180 on a 0.5 deg raster),
    from all photons (half None) or from one pseudo-random half. One pass over the
    emitters. The variance is exact for analog photons: a cell's count is binomial per
    emitter, var = sum over emitters of w^2 n (1 - n / N). ``symmetries``: only these."""
    gammas = np.asarray(gammas, np.float64)
    n, _, _, omega_grid = _blocks(float(c_step), tuple(gammas))
    folds = {}
    for name in symmetries:
        rep, kept = planes_kept(name, n)
        slot = np.full(n, -1, np.int64)
        slot[kept] = np.arange(len(kept))
        fold = np.zeros((len(kept), n))
        fold[slot[rep], np.arange(n)] = 1.0  # kept plane <- the planes folded into it
        folds[name] = (kept, fold)
    sums = {(name, h): [np.zeros((len(kept), len(gammas))) for _ in range(2)]
            for name, (kept, _) in folds.items() for h in HALVES}
    # the poles: caps of every width tried, all C planes pooled (flux and variance per
    # half; rows: the cap at gamma 0, at 180)
    cap_bins, cap_omega, cap_angles = _cap_bins(gammas)
    caps = {h: np.zeros((2, *cap_bins.shape)) for h in HALVES}
    halves = [list(acc.emitter_cells(h)) for h in (0, 1)]
    for (w2, n2, v0, i0), (_, _, v1, i1) in zip(*halves):
        k_half = [grid_counts(v0, i0, c_step, gammas), grid_counts(v1, i1, c_step, gammas)]
        r_half = [_cap_counts(ring_counts(v, i), cap_bins) for v, i in ((v0, i0), (v1, i1))]
        for h, k_all, pole, w, total in (
                (0, k_half[0], r_half[0], w2, n2), (1, k_half[1], r_half[1], w2, n2),
                (None, k_half[0] + k_half[1], r_half[0] + r_half[1], 0.5 * w2, 2.0 * n2)):
            for name, (_, fold) in folds.items():
                k = fold @ k_all
                f, v = sums[name, h]
                f += w * k
                v += w * w * k * np.maximum(1.0 - k / total, 0.0)
            caps[h][0] += w * pole
            caps[h][1] += w * w * pole * np.maximum(1.0 - pole / total, 0.0)
    out = {}
    widths = {}
    for (name, h), (flux, var) in sums.items():
        kept, fold = folds[name]
        omega = fold @ omega_grid
        cd, sigma = flux / omega, np.sqrt(var) / omega
        # gamma 0 and 180 are directions, not planes: one value each, shared by every
        # plane, from the whole polar cap (all planes' counts pooled), as wide as the
        # grid from all photons needs (the halves take the same caps)
        pole_cd, pole_sigma = caps[h][0] / cap_omega, np.sqrt(caps[h][1]) / cap_omega
        if name not in widths:
            all_flux, all_var = sums[name, None]
            widths[name] = pole_caps(all_flux / omega, np.sqrt(all_var) / omega,
                                     caps[None][0] / cap_omega,
                                     np.sqrt(caps[None][1]) / cap_omega)
        pick = widths[name]
        cd[:, [0, -1]] = pole_cd[[0, 1], pick]
        sigma[:, [0, -1]] = pole_sigma[[0, 1], pick]
        c = kept * c_step
        if name == "none":  # the 360 plane repeats 0, as the files list it
            c = np.append(c, 360.0)
            cd, sigma = np.vstack([cd, cd[:1]]), np.vstack([sigma, sigma[:1]])
        half_angles = (float(cap_angles[0, pick[0]]), float(cap_angles[1, pick[1]]))
        out[name, h] = CGammaGrid(c.astype(np.float64), gammas, cd, name, sigma, half_angles)
    return out


@functools.lru_cache(maxsize=16)
def _cap_bins_cached(gammas: tuple[float, ...]) -> tuple[np.ndarray, ...]:
    first = 0.5 * gammas[1], 0.5 * (180.0 - gammas[-2])  # to the midpoints: the grid's zones
    bins, omega, angles = [], [], []
    cos_edges = np.cos(np.radians(GAMMA_EDGES))
    for pole, start in enumerate(first):
        stop = max(start, POLE_CAP_MAX)
        half_angles = np.concatenate([[start], np.arange(
            math.ceil(start / POLE_CAP_STEP + 1e-9) * POLE_CAP_STEP, stop + 1e-9,
            POLE_CAP_STEP)])
        edge = half_angles if pole == 0 else 180.0 - half_angles
        b = np.searchsorted(GAMMA_EDGES, edge - 1e-9)
        if not np.allclose(GAMMA_EDGES[b], edge, atol=1e-9):
            raise LumitraceError("polar caps must end on goniometer gamma edges")
        bins.append(b)
        angles.append(half_angles)
        omega.append(2.0 * math.pi * (1.0 - cos_edges[b]) if pole == 0
                     else 2.0 * math.pi * (1.0 + cos_edges[b]))
    n = min(len(b) for b in bins)
    return tuple(np.array([a[:n] for a in x]) for x in (bins, omega, angles))


def _cap_bins(gammas: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The polar caps tried for a grid's poles: (the goniometer gamma edge index each
    ends at, their solid angles (sr), their half-angles (deg)), each (2, widths), row 0
    around gamma 0, row 1 around 180; the first the grid's own pole zone (to the midpoint
    to the next gamma)."""
    return _cap_bins_cached(tuple(map(float, gammas)))


def _cap_counts(ring: np.ndarray, cap_bins: np.ndarray) -> np.ndarray:
    """Counts of a ring profile (per goniometer gamma bin) in each polar cap, (2, widths)."""
    cum = np.concatenate([[0.0], np.cumsum(ring)])
    return np.stack([cum[cap_bins[0]], cum[-1] - cum[cap_bins[1]]])


def _median(x: np.ndarray) -> float:
    """np.median of finite values, without the NaN check that loads numpy.ma (20 ms)."""
    n = x.size
    part = np.partition(x, [(n - 1) // 2, n // 2])
    return float(np.mean(part[[(n - 1) // 2, n // 2]]))


def pole_caps(cd: np.ndarray, sigma: np.ndarray, cap_cd: np.ndarray, cap_sigma: np.ndarray
              ) -> np.ndarray:
    """Which polar cap each pole takes (index into the widths tried): the first unless the
    pole is lit and its relative error above :data:`POLE_NOISE` times the median of the
    grid's other lit values; then the first as quiet as that, or the widest."""
    inner = cd[:, 1:-1]
    top = max(float(inner.max(initial=0.0)), float(cap_cd[:, 0].max()))
    lit = inner >= LIT_SHARE * top
    if top <= 0 or not lit.any():
        return np.zeros(2, np.int64)
    limit = POLE_NOISE * _median(sigma[:, 1:-1][lit] / inner[lit])
    pick = np.zeros(2, np.int64)
    for p in (0, 1):
        if cap_cd[p, 0] < LIT_SHARE * top:
            continue
        rel = cap_sigma[p] / np.maximum(cap_cd[p], 1e-300)
        quiet = np.flatnonzero(rel <= limit)
        pick[p] = quiet[0] if quiet.size else len(rel) - 1
    return pick


def measure(acc: Accumulator, gammas: np.ndarray, c_step: float = 5.0,
            symmetry: str = "none", half: int | None = None) -> CGammaGrid:
    """One grid of :func:`measure_all`: ``symmetry``, from all photons or from ``half``."""
    return measure_all(acc, gammas, c_step)[symmetry, half]


def _unfolded(grid: CGammaGrid, values: np.ndarray, n: int) -> np.ndarray:
    """``values`` (kept planes, gammas) of a reduced grid on all ``n`` planes."""
    rep, kept = planes_kept(grid.symmetry, n)
    slot = np.full(n, -1, np.int64)
    slot[kept] = np.arange(len(kept))
    return values[slot[rep]]


def cell_solid_angle_grid(gammas: np.ndarray, c_step: float) -> np.ndarray:
    """Solid angle (sr) of every cell of the full grid, (planes, gammas)."""
    return _blocks(float(c_step), tuple(map(float, gammas)))[3]


def departure(base: CGammaGrid, reduced: CGammaGrid, c_step: float, margin: float = 3.0
              ) -> tuple[float, float, float]:
    """The distribution's relative RMS departure from ``reduced``'s symmetry, estimated
    from ``base`` (a grid of a weaker symmetry, all planes where it is "none"), the photon
    noise taken out: sqrt(sum dOmega ((I - I_sym)^2 - noise) / sum dOmega I^2) over the
    base's cells (the poles, which are directions, left out), with ``margin`` standard
    deviations of that sum taken off and added: (estimate, lower bound, upper bound). A
    base of a symmetry the scene is known to have averages its mirror images first, which
    leaves less noise to take out."""
    n = int(round(360.0 / c_step))
    rep_b, kept_b = planes_kept(base.symmetry, n)
    folded = np.bincount(rep_b, minlength=n)[kept_b]  # planes averaged into each base plane
    omega = cell_solid_angle_grid(base.gamma, c_step)[kept_b] * folded[:, None]
    i, s = base.candela[:len(kept_b)], base.sigma[:len(kept_b)]
    rep_s, kept_s = planes_kept(reduced.symmetry, n)
    slot = np.full(n, -1, np.int64)
    slot[kept_s] = np.arange(len(kept_s))
    group = slot[rep_s[kept_b]]  # the reduced plane each base plane is averaged into
    mean = reduced.candela[group]
    group_omega = np.zeros((len(kept_s), omega.shape[1]))
    np.add.at(group_omega, group, omega)
    group_omega = np.maximum(group_omega[group], 1e-300)
    var_mean = np.zeros((len(kept_s), omega.shape[1]))
    np.add.at(var_mean, group, (omega * s) ** 2)
    var_mean = var_mean[group] / group_omega ** 2
    noise = s ** 2 * (1.0 - 2.0 * omega / group_omega) + var_mean
    inner = slice(1, -1)  # the poles are one direction: the same in every plane
    num = float((omega * ((i - mean) ** 2 - noise))[:, inner].sum())
    spread = margin * float(np.sqrt(2.0 * ((omega * noise)[:, inner] ** 2).sum()))
    den = float((omega * i ** 2).sum())
    if den <= 0:
        return 0.0, 0.0, 0.0
    return tuple(math.sqrt(max(x, 0.0) / den) for x in (num, num - spread, num + spread))


def asymmetry(full: CGammaGrid, reduced: CGammaGrid, c_step: float,
              margin: float = 0.0) -> float:
    """Estimated true relative RMS departure of the distribution from ``reduced``'s
    symmetry (:func:`departure` from ``full``); ``margin`` standard deviations of the sum
    taken off first: a lower confidence bound."""
    return departure(full, reduced, c_step, margin)[1]


#: What each symmetry maps onto itself under: reflections across the C0-C180 plane ("y")
#: and the C90-C270 plane ("x"), and every rotation about the vertical axis ("r").
GENERATORS = {"none": frozenset(), "C0-C180": frozenset("y"), "C90-C270": frozenset("x"),
              "quadrant": frozenset("xy"), "octant": frozenset("xy4"),
              "rotational": frozenset("xy4r")}
#: How a symmetry was chosen: declared on the stage, shown by the geometry, shown by the
#: counts (the upper bound of the departure within the tolerance), or none shown.
SOURCES = ("declared", "geometry", "measured", "none")


@dataclass(frozen=True)
class SymmetryChoice:
    """The symmetry the files are averaged over and why (:data:`SOURCES`); ``settled``:
    no stronger symmetry could still be shown by more photons (each one's departure is
    shown above the tolerance by its lower bound); ``departures``: per symmetry tried,
    (estimate, lower, upper bound) of the relative RMS departure; ``known``: the symmetry
    declared or shown by the geometry that the counts started from."""

    name: str
    source: str
    settled: bool
    departures: dict
    known: str = "none"
    #: a declared symmetry the counts show a departure from (its lower bound above the
    #: tolerance)
    contradicted: bool = False

    @property
    def files(self) -> str:
        """The symmetry the files are written with (an octant as its quadrant)."""
        return "quadrant" if self.name == "octant" else self.name

    def describe(self) -> str:
        """One line: the symmetry and why, as the files' headers and the summary say it."""
        why = {"declared": "declared on the stage", "geometry": "shown by the geometry",
               "measured": "shown by the photon counts", "none": "none shown"}[self.source]
        extra = " and the 90 deg rotation" if self.name == "octant" else ""
        return f"{self.files}{extra} ({why})"


def symmetric_grid(acc: Accumulator, gammas: np.ndarray, c_step: float, tolerance: float,
                   known: str = "none", declared: bool = False
                   ) -> tuple[CGammaGrid, tuple[CGammaGrid, CGammaGrid], SymmetryChoice]:
    """The files' grid, averaged on the counts over the symmetry chosen so: a ``declared``
    one as declared; else the ``known`` one (shown by the geometry), or a stronger one
    where the counts show it: the upper bound (3 sigma) of the departure from it, measured
    from the known one's grid, within ``tolerance`` (relative RMS). Never a symmetry from
    a lack of evidence. Returns the grid, the same grid from each half of the photons, and
    the choice. An octant (a square luminaire) is written as its quadrant."""
    stronger = [name for name in CANDIDATES if GENERATORS[known] < GENERATORS[name]]
    grids = measure_all(acc, gammas, c_step, tuple(dict.fromkeys(("none", known, *stronger))))
    bounds = {name: departure(grids[known, None], grids[name, None], c_step)
              for name in stronger}
    if declared:
        against = departure(grids["none", None], grids[known, None], c_step) \
            if known != "none" else (0.0, 0.0, 0.0)
        choice = SymmetryChoice(known, "declared", True, bounds, known,
                                contradicted=against[1] > tolerance)
    else:
        shown = [name for name in stronger if bounds[name][2] <= tolerance]
        name = shown[0] if shown else known
        source = "measured" if shown else ("geometry" if known != "none" else "none")
        # still open: a symmetry not implied by the chosen one whose bounds straddle
        open_ = [other for other in stronger if not GENERATORS[other] <= GENERATORS[name]
                 and bounds[other][1] <= tolerance]
        choice = SymmetryChoice(name, source, not open_, bounds, known)
    picked = [grids[choice.name, h] for h in HALVES]
    if choice.name == "octant":
        picked = [_quadrant_of_octant(g, c_step) for g in picked]
    return picked[0], (picked[1], picked[2]), choice


def _quadrant_of_octant(grid: CGammaGrid, c_step: float) -> CGammaGrid:
    """An octant's grid (planes 0 .. 45 deg) on a quadrant's planes (0 .. 90 deg), each
    plane C > 45 deg the plane 90 - C."""
    n = int(round(360.0 / c_step))
    k = np.arange(n // 4 + 1)
    src = np.where(k <= n // 8, k, n // 4 - k)
    return replace(grid, c=k * c_step, candela=grid.candela[src],
                   sigma=None if grid.sigma is None else grid.sigma[src], symmetry="quadrant")
