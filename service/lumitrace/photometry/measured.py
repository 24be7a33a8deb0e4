"""Photometry measured by the virtual goniophotometer: intensities (cd) on a C-gamma grid with
their standard errors, symmetry judged against the counts' own noise, and symmetry averaging
done on the counts.

A grid value is a point value in gamma, as every lighting program reads a photometric file:
the intensity at its listed gamma, from a parabola fitted to the goniometer's 0.25 deg gamma
bins around it (to its nearer neighbour, at least three bins each side), within its
plane's C cell (C +- half the C step, whose mean it is). The fit is a fixed linear
combination of bin counts, so its variance is exact (binomial, analog photons) and its bias
third order in the window where the distribution is smooth (a cell's mean over a beam's
curved flank is off by the curvature; a reader integrating cell means as point values
misses a narrow beam's flux by percents). The poles, gamma 0 and 180, are directions, not
planes: their value, the same in every plane, is an even parabola's over a polar cap (all
C), from the pole to the midpoint to the next gamma (at least :data:`LEAST_WINDOW`) or,
where the pole is lit (at least :data:`LIT_SHARE` of the grid's largest value) and that
cap is noisier than :data:`POLE_NOISE` times the median relative error of the grid's
other lit values, as far as it takes to be no noisier than that (0.5 deg steps, at most
:data:`POLE_CAP_MAX` deg: the even parabola's value is four times as variable as the cap's
mean, but not off by the curvature). Nothing is filtered. At a kink (the horizon of a
one-sided disc) a fitted value lies between the two sides; where a parabola dips below
zero (the foot of a sharp cut-off) the value is the mean of the bins beside it, which
cannot.
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
POLE_CAP_MAX = 15.0
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


def plane_bins(values: np.ndarray, idx: np.ndarray | None, c_step: float) -> np.ndarray:
    """An emitter's goniometer counts (dense, or at bins ``idx``) summed over each C plane's
    bins (plane 0 holds those either side of C = 0), kept per goniometer gamma bin:
    (planes, N_GAMMA) float64."""
    plane, n = _plane_of_bin(float(c_step))
    per = N_C // n
    if idx is None:
        fine = values[:N_CELLS].reshape(N_C, N_GAMMA)  # integer sums: exact
        return np.roll(fine, per // 2, axis=0).reshape(n, per, N_GAMMA).sum(axis=1).astype(
            np.float64)
    keep = idx < N_CELLS
    ci, gi = np.divmod(idx[keep], N_GAMMA)
    return np.bincount(plane[ci] * N_GAMMA + gi, weights=values[keep].astype(np.float64),
                       minlength=n * N_GAMMA).reshape(n, N_GAMMA)


def cell_fluxes(acc: Accumulator, gammas: np.ndarray, c_step: float = 5.0) -> np.ndarray:
    """The photon flux (lm) through every cell of a C-gamma grid: C cells of ``c_step``
    around each plane by gamma zones between the midpoints of ``gammas`` (0.5 deg raster),
    (planes, gammas). The raw counts a cell's mean would be made of (what a test of the
    tracer or a peer's grid compares), not the files' values."""
    g = np.asarray(gammas, np.float64)
    mids = np.concatenate([[0.0], 0.5 * (g[1:] + g[:-1])])
    starts = np.searchsorted(GAMMA_EDGES, mids - 1e-9)
    if not np.allclose(GAMMA_EDGES[starts], mids, atol=1e-9):
        raise LumitraceError("grid gammas must lie on a 0.5 deg raster")
    out = 0.0
    for w, _, values, idx in acc.emitter_cells():
        out = out + w * np.add.reduceat(plane_bins(values, idx, c_step), starts, axis=1)
    return np.asarray(out, np.float64) * np.ones((int(round(360.0 / c_step)), len(g)))


#: Gauss-Legendre nodes and weights on [0, 1] (3 points): a bin's moments.
_GL_X = 0.5 + 0.5 * np.array([-math.sqrt(0.6), 0.0, math.sqrt(0.6)])
_GL_W = np.array([5.0, 8.0, 5.0]) / 18.0
#: The narrowest window (deg each side) a listed angle's parabola is fitted over: three
#: bins of 0.25 deg at least.
LEAST_WINDOW = 0.375


def _fit_rows(centres: np.ndarray, bins: np.ndarray, use: np.ndarray,
              powers: tuple[int, ...]) -> np.ndarray:
    """For each listed angle (``centres``, deg), the weights of its bins (``bins`` (G, W),
    those with ``use`` (G, W)) in the value at it of the polynomial in (gamma - centre)
    with ``powers`` fitted to the bins' mean intensities by least squares, each bin
    weighted by its solid angle (the photons a flat distribution puts there); the
    polynomial's bin means are its solid-angle means over the bins (3-point Gauss-Legendre
    in each bin): (G, W)."""
    b = np.clip(bins, 0, N_GAMMA - 1)
    lo, hi = np.radians(GAMMA_EDGES[b]), np.radians(GAMMA_EDGES[b + 1])
    x = lo[..., None] + (hi - lo)[..., None] * _GL_X  # (G, W, 3)
    w = np.sin(x) * _GL_W
    w = np.where(w.sum(axis=-1, keepdims=True) > 0, w, _GL_W)
    u = x - np.radians(centres)[:, None, None]
    a = np.stack([(w * u ** p).sum(axis=-1) / w.sum(axis=-1) for p in powers], axis=-1)
    om = np.where(use, -np.diff(np.cos(np.radians(GAMMA_EDGES)))[b], 0.0)  # (G, W)
    ata = np.einsum("gwi,gw,gwj->gij", a, om, a)
    rhs = np.einsum("gwi,gw->giw", a, om)
    return np.linalg.solve(ata, rhs)[:, 0, :]


@functools.lru_cache(maxsize=16)
def point_operators(gammas: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                         np.ndarray]:
    """How a profile's goniometer gamma bins (mean intensities) give point values at the
    listed ``gammas``: for every listed angle, the first bin it uses (G,) and the weights
    of its bins from there, of the fit and of the window's mean (2, G, width; the poles'
    rows 0); for each pole and each polar window tried, the bins' weights, of the fit and
    of the cap's mean (2, 2, windows, N_GAMMA), and the windows' half-angles (2, windows,
    deg). A listed angle's value is the value there of a parabola fitted to
    the bins within its window (to its nearer neighbour, at least :data:`LEAST_WINDOW`
    deg each side): unbiased to second order where the distribution curves, as a beam's
    flank does, where a cell's mean is not (and a reader takes a value as the intensity
    at its angle). A pole's value is an even parabola's (I(u) = a + b u^2) over a polar
    cap, all C pooled."""
    g = np.asarray(gammas, np.float64)
    centres = 0.5 * (GAMMA_EDGES[1:] + GAMMA_EDGES[:-1])
    inner = g[1:-1]
    reach = np.maximum(LEAST_WINDOW, np.minimum(inner - g[:-2], g[2:] - inner))
    lo = np.searchsorted(centres, inner - reach - 1e-9)
    hi = np.searchsorted(centres, inner + reach + 1e-9)
    width = int((hi - lo).max())
    first = np.minimum(lo, N_GAMMA - width)
    bins = first[:, None] + np.arange(width)[None, :]
    use = (bins >= lo[:, None]) & (bins < hi[:, None])
    weights = np.zeros((2, len(g), width))
    weights[0, 1:-1] = np.where(use, _fit_rows(inner, bins, use, (0, 1, 2)), 0.0)
    # the fallback: the mean of the two bins beside the angle (the narrowest there is)
    near = np.abs(centres[np.clip(bins, 0, N_GAMMA - 1)] - inner[:, None]) <= 0.25 + 1e-9
    weights[1, 1:-1] = _window_means(bins, use & near)
    first = np.concatenate([[0], first, [0]])
    # the poles: windows from the grid's own pole zone (to the midpoint to the next
    # gamma, at least LEAST_WINDOW) widening in POLE_CAP_STEP steps to POLE_CAP_MAX
    starts = (max(LEAST_WINDOW, 0.5 * g[1]), max(LEAST_WINDOW, 0.5 * (180.0 - g[-2])))
    n_win = 1 + int(math.floor((POLE_CAP_MAX - min(starts)) / POLE_CAP_STEP + 1e-9))
    poles = np.zeros((2, 2, n_win, N_GAMMA))
    angles = np.zeros((2, n_win))
    for p, start in enumerate(starts):
        half = np.minimum(start + np.arange(n_win) * POLE_CAP_STEP, max(POLE_CAP_MAX, start))
        pole = 0.0 if p == 0 else 180.0
        dist = np.abs(centres - pole)
        inside = dist[None, :] <= half[:, None] + 1e-9  # (windows, N_GAMMA)
        wide = int(inside.sum(axis=1).max())
        nearest = np.argsort(dist, kind="stable")[:wide]
        rows = _fit_rows(np.full(n_win, pole), np.broadcast_to(nearest, (n_win, wide)),
                         inside[:, nearest], (0, 2))
        poles[0, p][:, nearest] = np.where(inside[:, nearest], rows, 0.0)
        poles[1, p][:, nearest] = _window_means(np.broadcast_to(nearest, (n_win, wide)),
                                                inside[:, nearest] & (dist[nearest] <= 0.25))
        angles[p] = half
    for shared in (first, weights, poles, angles):
        shared.flags.writeable = False
    return first, weights, poles, angles


def _window_means(bins: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Weights (G, W) of bins ``bins`` (G, W) used where ``use`` in their solid-angle
    mean: a window's mean intensity."""
    om = np.where(use, -np.diff(np.cos(np.radians(GAMMA_EDGES)))[np.clip(bins, 0,
                                                                        N_GAMMA - 1)], 0.0)
    return om / om.sum(axis=1, keepdims=True)


def _nonnegative(fit, fit_var, mean, mean_var):
    """The fitted values, or where a parabola dips below zero (the foot of a cut-off, a
    dark region's noise) the mean of the bins beside the angle, which cannot: (values,
    standard errors)."""
    low = fit < 0
    return np.where(low, mean, fit), np.sqrt(np.where(low, mean_var, fit_var))


def _points(means: np.ndarray, var: np.ndarray, first: np.ndarray, weights: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """Point values (planes, G) and their standard errors from the planes' bin means
    (planes, N_GAMMA) and the means' variances, by the listed angles' bin weights (fit,
    window mean; :func:`_nonnegative`)."""
    take = first[:, None] + np.arange(weights.shape[2])[None, :]  # (G, width)
    m, v = means[:, take], var[:, take]
    fit, mean = (np.einsum("pgw,gw->pg", m, w) for w in weights)
    fit_var, mean_var = (np.einsum("pgw,gw->pg", v, w * w) for w in weights)
    return _nonnegative(fit, fit_var, mean, mean_var)


def _pole_points(poles: np.ndarray, mean: np.ndarray, var: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Each pole's value and standard error for every cap tried, (2, windows) each, from
    the ring's bin means and their variances (:func:`_nonnegative`)."""
    fit, cap = (np.einsum("pkb,b->pk", w, mean) for w in poles)
    fit_var, cap_var = (np.einsum("pkb,b->pk", w * w, var) for w in poles)
    return _nonnegative(fit, fit_var, cap, cap_var)


def measure_all(acc: Accumulator, gammas: np.ndarray, c_step: float = 5.0,
                symmetries: tuple[str, ...] = SYMMETRY_NAMES
                ) -> dict[tuple[str, int | None], CGammaGrid]:
    """The goniophotometer's C-gamma grids (cd) with standard errors (``sigma``, cd), keyed
    by (symmetry, half): planes every ``c_step`` deg (averaged over the mirror images the
    symmetry names, on the counts), point values at the listed ``gammas`` (deg, 0 .. 180;
    :func:`point_operators`), from all photons (half None) or from one pseudo-random half.
    In C each value is the mean over its plane's C cell (C +- half the C step). One pass
    over the emitters. The variance is exact for analog photons: a bin's count is binomial
    per emitter, var = sum over emitters of w^2 n (1 - n / N), and a value is a fixed
    linear combination of bins."""
    gammas = np.asarray(gammas, np.float64)
    first, weights, poles, pole_angles = point_operators(tuple(map(float, gammas)))
    _, n = _plane_of_bin(float(c_step))
    per = N_C // n
    omega_plane = np.broadcast_to(cell_solid_angles()[:per].sum(axis=0), (n, N_GAMMA))
    folds = {}
    for name in symmetries:
        rep, kept = planes_kept(name, n)
        slot = np.full(n, -1, np.int64)
        slot[kept] = np.arange(len(kept))
        order = np.argsort(slot[rep], kind="stable")
        starts = np.flatnonzero(np.r_[True, np.diff(slot[rep][order]) != 0])
        folds[name] = (kept, order, starts)
    sums = {(name, h): [np.zeros((len(kept), N_GAMMA)) for _ in range(2)]
            for name, (kept, _, _) in folds.items() for h in HALVES}
    rings = {h: np.zeros((2, N_GAMMA)) for h in HALVES}  # all C pooled: the poles
    halves = [list(acc.emitter_cells(h)) for h in (0, 1)]
    for (w2, n2, v0, i0), (_, _, v1, i1) in zip(*halves):
        k_half = [plane_bins(v0, i0, c_step), plane_bins(v1, i1, c_step)]
        for h, k_all, w, total in ((0, k_half[0], w2, n2), (1, k_half[1], w2, n2),
                                   (None, k_half[0] + k_half[1], 0.5 * w2, 2.0 * n2)):
            for name, (_, order, starts) in folds.items():
                k = np.add.reduceat(k_all[order], starts, axis=0)
                f, v = sums[name, h]
                f += w * k
                v += w * w * k * np.maximum(1.0 - k / total, 0.0)
            ring = k_all.sum(axis=0)
            rings[h][0] += w * ring
            rings[h][1] += w * w * ring * np.maximum(1.0 - ring / total, 0.0)
    ring_omega = n * omega_plane[0]
    out, widths = {}, {}
    for (name, h), (flux, var) in sums.items():
        kept, order, starts = folds[name]
        omega = np.add.reduceat(omega_plane[order], starts, axis=0)
        cd, sigma = _points(flux / omega, var / omega ** 2, first, weights)
        # gamma 0 and 180 are directions, not planes: one value each, shared by every
        # plane, from a polar cap (all planes' counts pooled), as wide as the grid from
        # all photons needs (the halves take the same caps)
        ring_mean, ring_var = rings[h][0] / ring_omega, rings[h][1] / ring_omega ** 2
        pole_cd, pole_sigma = _pole_points(poles, ring_mean, ring_var)
        if name not in widths:
            all_cd, all_sigma = (cd, sigma) if h is None else _points(
                sums[name, None][0] / omega, sums[name, None][1] / omega ** 2, first, weights)
            all_ring = rings[None][0] / ring_omega, rings[None][1] / ring_omega ** 2
            widths[name] = pole_caps(all_cd, all_sigma, *_pole_points(poles, *all_ring))
        pick = widths[name]
        cd[:, [0, -1]] = pole_cd[[0, 1], pick]
        sigma[:, [0, -1]] = pole_sigma[[0, 1], pick]
        c = kept * c_step
        if name == "none":  # the 360 plane repeats 0, as the files list it
            c = np.append(c, 360.0)
            cd, sigma = np.vstack([cd, cd[:1]]), np.vstack([sigma, sigma[:1]])
        half_angles = (float(pole_angles[0, pick[0]]), float(pole_angles[1, pick[1]]))
        out[name, h] = CGammaGrid(c.astype(np.float64), gammas, cd, name, sigma, half_angles)
    return out


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
    """Solid angle (sr) each value of the full grid stands for, (planes, gammas): its C
    cell by the zone between the midpoints to its neighbouring gammas (the quadrature a
    flux or an RMS over the sphere takes)."""
    g = np.radians(np.asarray(gammas, np.float64))
    edges = np.concatenate([[0.0], 0.5 * (g[1:] + g[:-1]), [math.pi]])
    zone = np.cos(edges[:-1]) - np.cos(edges[1:])
    n = int(round(360.0 / c_step))
    return np.broadcast_to(math.radians(c_step) * zone, (n, len(g)))


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
