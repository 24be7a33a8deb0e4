"""The C-gamma grid of type C photometry: intensities on C planes by gamma angles, with
their symmetry, as the IES and EULUMDAT files hold them (the goniophotometer's measured
grids are built in :mod:`lumitrace.photometry.measured`)."""
from __future__ import annotations

from dataclasses import dataclass, replace

import math

import numpy as np


#: Symmetries of type C photometry, by the C range they need (LM-63 horizontal angles).
SYMMETRIES = {
    "none": (0.0, 360.0),
    "C0-C180": (0.0, 180.0),     # mirror symmetric about the C0-C180 plane
    "C90-C270": (90.0, 270.0),   # mirror symmetric about the C90-C270 plane
    "quadrant": (0.0, 90.0),     # both planes
    "rotational": (0.0, 0.0),    # about the vertical axis
}


@dataclass(frozen=True)
class CGammaGrid:
    """Intensities (cd) on C planes (deg) by gamma angles (deg): ``candela[i, j]`` is at
    ``c[i]``, ``gamma[j]``. ``symmetry`` says which C range the planes cover."""

    c: np.ndarray
    gamma: np.ndarray
    candela: np.ndarray
    symmetry: str = "none"
    sigma: np.ndarray | None = None  # standard error of each value (cd), where known
    #: half-angles (deg) of the polar caps whose mean intensity the gamma 0 and 180 values
    #: are (measured grids; None for a grid read from a file)
    pole_caps: tuple[float, float] | None = None

    def full(self) -> "CGammaGrid":
        """The same distribution on planes all round (0 <= C < 360), unfolding symmetry."""
        if self.symmetry == "none":
            keep = self.c < 360.0 - 1e-9
            return replace(self, c=self.c[keep], candela=self.candela[keep],
                           sigma=None if self.sigma is None else self.sigma[keep])
        step = _c_step(self.c)
        cs = np.arange(0.0, 360.0 - 1e-9, step)
        return CGammaGrid(cs, self.gamma, self.at(cs), "none",
                          None if self.sigma is None else self.at(cs, self.sigma),
                          self.pole_caps)

    def at(self, c_deg: np.ndarray, values: np.ndarray | None = None) -> np.ndarray:
        """Intensity rows (len(c), len(gamma)) at any C angles, using the symmetry (or rows
        of ``values``, shaped like ``candela``, such as ``sigma``)."""
        table = self.candela if values is None else values
        c = np.mod(np.asarray(c_deg, dtype=np.float64), 360.0)
        if self.symmetry == "rotational":
            return np.repeat(table[:1], len(c), axis=0)
        if self.symmetry == "C0-C180":
            c = np.where(c > 180.0, 360.0 - c, c)
        elif self.symmetry == "C90-C270":
            c = np.where(c < 90.0, 180.0 - c, np.where(c > 270.0, 540.0 - c, c))
        elif self.symmetry == "quadrant":
            c = np.where(c > 180.0, 360.0 - c, c)
            c = np.where(c > 90.0, 180.0 - c, c)
        src_c, src = self.c, table
        if self.symmetry == "none" and src_c[-1] < 360.0 - 1e-9:
            src_c = np.append(src_c, 360.0)
            src = np.vstack([src, src[:1]])
        return _interp_rows(c, src_c, src)

    def flux(self) -> float:
        """Luminous flux (lm) by zonal integration: gamma zones between sample midpoints,
        C sectors between plane midpoints, intensity constant over each cell."""
        g = self.full()
        cos_edges = np.cos(np.radians(_midpoint_edges(g.gamma, 0.0, 180.0)))
        zone = cos_edges[:-1] - cos_edges[1:]  # solid angle per unit azimuth
        dc = np.radians(_periodic_widths(g.c))
        return float((g.candela * dc[:, None] * zone[None, :]).sum())

    @property
    def peak(self) -> tuple[float, float, float]:
        """(cd, C deg, gamma deg) of the highest intensity."""
        i, j = np.unravel_index(int(np.argmax(self.candela)), self.candela.shape)
        return float(self.candela[i, j]), float(self.c[i]), float(self.gamma[j])


def _interp_rows(x: np.ndarray, xp: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``np.interp`` of every column of ``rows`` (len(xp), n) at ``x`` at once: linear
    between the rows, clamped to the first and last beyond them."""
    x = np.clip(x, xp[0], xp[-1])
    if len(xp) == 1:
        return np.repeat(rows[:1], len(x), axis=0)
    i = np.clip(np.searchsorted(xp, x, side="right") - 1, 0, len(xp) - 2)
    slope = (rows[i + 1] - rows[i]) / (xp[i + 1] - xp[i])[:, None]
    return rows[i] + slope * (x - xp[i])[:, None]


def _c_step(c: np.ndarray) -> float:
    d = np.diff(c)
    return float(d.min()) if d.size else 5.0


def _midpoint_edges(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    mids = 0.5 * (x[1:] + x[:-1])
    return np.concatenate([[lo], mids, [hi]])


def _periodic_widths(c: np.ndarray) -> np.ndarray:
    """Angular width (deg) of the sector each C plane stands for, all round the axis."""
    if len(c) == 1:
        return np.array([360.0])
    nxt = np.append(c[1:], c[0] + 360.0)
    prv = np.insert(c[:-1], 0, c[-1] - 360.0)
    return 0.5 * (nxt - prv)


def default_gammas(peak_half_width_deg: float | None = None) -> np.ndarray:
    """Gamma angles: every 2.5 deg, and finer within three half-widths of a narrow beam
    (half width below 15 deg), as test labs list narrow beams: every 0.5 deg, down to
    every 0.125 deg (an eighth of the half width), so that a reader integrating the values
    as points, trapezoid by trapezoid, finds the beam's flux."""
    g = np.arange(0.0, 180.0 + 1e-9, 2.5)
    if peak_half_width_deg is not None and peak_half_width_deg < 15.0:
        step = min(0.5, max(0.125, math.floor(peak_half_width_deg / 8.0 / 0.125) * 0.125))
        fine = np.arange(0.0, min(180.0, 3.0 * max(peak_half_width_deg, 1.0)) + 1e-9, step)
        g = np.sort(np.concatenate([g, fine]))  # np.union1d would load numpy.ma (20 ms)
        g = g[np.append(True, g[1:] - g[:-1] > 1e-9)]
    return g


class NormalDraws:
    """Standard normal draws for the figures' bootstrap, a pure function of a seed and the
    draws made before: counters hashed (MurmurHash3's 64-bit finaliser, as
    :func:`lumitrace.trace.rng.fmix64` has it for the photons; photometry does not import
    the tracer, and the kernels compile that module's constants in) into uniform pairs,
    made normal by the Box-Muller transform. A ``numpy.random.Generator`` serves alike (its
    ``standard_normal``), but loading numpy.random costs every run 10 ms."""

    _M1, _M2 = np.uint64(0xFF51AFD7ED558CCD), np.uint64(0xC4CEB9FE1A85EC53)

    def __init__(self, seed: int = 0):
        self._key = np.uint64((seed * 0x9E3779B97F4A7C15 + 1) & 0xFFFFFFFFFFFFFFFF)
        self._drawn = 0

    def _uniforms(self, n: int) -> np.ndarray:
        """``n`` uniforms in (0, 1], 53 bits each, from the next ``n`` counters."""
        k = np.arange(self._drawn, self._drawn + n, dtype=np.uint64) ^ self._key
        self._drawn += n
        for m in (self._M1, self._M2):
            k = (k ^ (k >> np.uint64(33))) * m
        k ^= k >> np.uint64(33)
        return ((k >> np.uint64(11)).astype(np.float64) + 1.0) * 2.0 ** -53

    def standard_normal(self, shape=None) -> np.ndarray | float:
        """Independent standard normal values of ``shape`` (a float where None)."""
        n = int(np.prod(shape)) if shape is not None else 1
        half = (n + 1) // 2
        u = self._uniforms(2 * half)
        r, phi = np.sqrt(-2.0 * np.log(u[:half])), 2.0 * np.pi * u[half:]
        z = np.concatenate([r * np.cos(phi), r * np.sin(phi)])[:n]
        return float(z[0]) if shape is None else z.reshape(shape)


def redrawn(grid: CGammaGrid, rng, draws: int | None = None,
            rows: np.ndarray | None = None) -> np.ndarray:
    """``grid``'s values (its planes ``rows``, default all) redrawn within their errors
    (normal, from ``rng``'s ``standard_normal``: :class:`NormalDraws` or numpy's
    Generator), one draw per value the grid holds (``draws`` of them stacked first, or one):
    the mirror images a symmetry folds into one value move together, as do the planes'
    shared pole values and the 360 deg plane that repeats 0."""
    rows = np.arange(len(grid.c)) if rows is None else np.asarray(rows)
    shape = (len(rows), len(grid.gamma)) if draws is None else \
        (draws, len(rows), len(grid.gamma))
    noise = grid.sigma[rows] * rng.standard_normal(shape)
    noise[..., :, 0] = noise[..., :1, 0]  # gamma 0 and 180: directions, one value each
    noise[..., :, -1] = noise[..., :1, -1]
    if grid.symmetry == "none" and len(grid.c) > 1 and grid.c[-1] >= 360.0 - 1e-9:
        first, last = np.flatnonzero(rows == 0), np.flatnonzero(rows == len(grid.c) - 1)
        if len(first) and len(last):
            noise[..., last[0], :] = noise[..., first[0], :]
    return grid.candela[rows] + noise
