"""Photometry measured by the virtual goniophotometer: intensities (cd) on a C-gamma grid with
their standard errors, symmetry judged against the counts' own noise, and symmetry averaging
done on the counts.

A grid value is the photon flux through its cell (C +- half the C step, gamma between the
midpoints to its neighbours) over the cell's solid angle: an unbiased estimate of the mean
intensity over the cell, with the exact binomial variance of analog photons. Nothing is
interpolated or filtered, so the files carry no bias the stated errors do not cover, beyond
the averaging over each cell (second order in the cell size where the distribution is
smooth; at a kink, such as the horizon of a one-sided disc, the cell's mean).
"""
from __future__ import annotations

import numpy as np

from ..errors import LumitraceError
from ..film.accumulate import Accumulator
from ..film.goniometer import C_STEP, GAMMA_EDGES, N_BINS, N_C, N_CELLS, cell_solid_angles
from .grid import CGammaGrid

#: Symmetries tried, strongest first.
CANDIDATES = ("rotational", "quadrant", "C0-C180", "C90-C270")


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
    raise ValueError(f"unknown symmetry {symmetry!r}")


def measure(acc: Accumulator, gammas: np.ndarray, c_step: float = 5.0,
            symmetry: str = "none", half: int | None = None) -> CGammaGrid:
    """The goniophotometer's C-gamma grid (cd) with standard errors (``sigma``, cd): planes
    every ``c_step`` deg (averaged over the mirror images ``symmetry`` names, on the
    counts), gammas ``gammas`` (deg, 0 .. 180 on a 0.5 deg raster). ``half``: from that
    pseudo-random half of the photons alone."""
    plane, n = _plane_of_bin(c_step)
    zone = _zone_of_bin(gammas)
    rep, kept = planes_kept(symmetry, n)
    slot = np.full(n, -1, np.int64)
    slot[kept] = np.arange(len(kept))
    ng = len(gammas)
    group = np.full(N_BINS, -1, np.int64)
    group[:N_CELLS] = (slot[rep[plane]][:, None] * ng + zone[None, :]).ravel()
    groups = len(kept) * ng
    flux, var, _ = acc.binned(group, groups, half)
    omega = np.bincount(group[:N_CELLS], weights=cell_solid_angles().ravel(), minlength=groups)
    shape = (len(kept), ng)
    cd = (flux / omega).reshape(shape)
    sigma = (np.sqrt(var) / omega).reshape(shape)
    c = kept * c_step
    if symmetry == "none":  # the 360 plane repeats 0, as the files list it
        c = np.append(c, 360.0)
        cd, sigma = np.vstack([cd, cd[:1]]), np.vstack([sigma, sigma[:1]])
    return CGammaGrid(c.astype(np.float64), np.asarray(gammas, np.float64), cd, symmetry,
                      sigma)


def _unfolded(grid: CGammaGrid, values: np.ndarray, n: int) -> np.ndarray:
    """``values`` (kept planes, gammas) of a reduced grid on all ``n`` planes."""
    rep, kept = planes_kept(grid.symmetry, n)
    slot = np.full(n, -1, np.int64)
    slot[kept] = np.arange(len(kept))
    return values[slot[rep]]


def cell_solid_angle_grid(gammas: np.ndarray, c_step: float) -> np.ndarray:
    """Solid angle (sr) of every cell of the full grid, (planes, gammas)."""
    plane, n = _plane_of_bin(c_step)
    zone = _zone_of_bin(gammas)
    ng = len(gammas)
    idx = (plane[:, None] * ng + zone[None, :]).ravel()
    return np.bincount(idx, weights=cell_solid_angles().ravel(), minlength=n * ng).reshape(n, ng)


def asymmetry(full: CGammaGrid, reduced: CGammaGrid, c_step: float,
              margin: float = 0.0) -> float:
    """Estimated true relative RMS departure of the distribution from ``reduced``'s
    symmetry, the photon noise taken out: sqrt(max(0, sum dOmega ((I - I_sym)^2 -
    noise)) / sum dOmega I^2), ``full`` being the grid without symmetry. ``margin``
    standard deviations of that sum are taken off first: a lower confidence bound."""
    n = int(round(360.0 / c_step))
    omega = cell_solid_angle_grid(full.gamma, c_step)
    i, s = full.candela[:n], full.sigma[:n]
    mean = _unfolded(reduced, reduced.candela, n)
    rep, _ = planes_kept(reduced.symmetry, n)
    # omega of each cell's group: the sum over the planes folded into the same kept plane
    group_omega = np.zeros_like(omega)
    np.add.at(group_omega, rep, omega)
    group_omega = group_omega[rep]
    var_mean = np.zeros_like(omega)
    np.add.at(var_mean, rep, (omega * s) ** 2)
    var_mean = var_mean[rep] / np.maximum(group_omega, 1e-300) ** 2
    noise = s ** 2 * (1.0 - 2.0 * omega / np.maximum(group_omega, 1e-300)) + var_mean
    num = float((omega * ((i - mean) ** 2 - noise)).sum())
    num -= margin * float(np.sqrt(2.0 * ((omega * noise) ** 2).sum()))
    den = float((omega * i ** 2).sum())
    return float(np.sqrt(max(num, 0.0) / den)) if den > 0 else 0.0


def symmetric_grid(acc: Accumulator, gammas: np.ndarray, c_step: float,
                   tolerance: float) -> tuple[CGammaGrid, dict[str, float]]:
    """The grid of the strongest symmetry the counts do not show a departure from larger
    than ``tolerance`` (relative RMS; :func:`asymmetry` at a 3 sigma lower bound), averaged
    on the counts; the full grid when there is none. Also returns every candidate's
    estimated departure."""
    full = measure(acc, gammas, c_step)
    departures = {}
    chosen = None
    for name in CANDIDATES:
        reduced = measure(acc, gammas, c_step, name)
        departures[name] = asymmetry(full, reduced, c_step)
        if chosen is None and asymmetry(full, reduced, c_step, 3.0) <= tolerance:
            chosen = reduced
    return (chosen if chosen is not None else full), departures

