"""The C-gamma grid of type C photometry, resampled from the cube-map intensity map.

Intensities are looked up bilinearly in the cube map at every (C, gamma) of the grid and
scaled by one factor so that the flux integrated from the grid equals the map's flux (the
bilinear lookup and the zonal integration each err by a little; the product is what lighting
software integrates). Symmetry is detected from the data and used only where it holds
within the map's own noise: then the grid holds the mean of the mirrored halves.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..film.cubemap import sample_map, texel_solid_angles
from . import frame

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

    def full(self) -> "CGammaGrid":
        """The same distribution on planes all round (0 <= C < 360), unfolding symmetry."""
        if self.symmetry == "none":
            keep = self.c < 360.0 - 1e-9
            return replace(self, c=self.c[keep], candela=self.candela[keep],
                           sigma=None if self.sigma is None else self.sigma[keep])
        step = _c_step(self.c)
        cs = np.arange(0.0, 360.0 - 1e-9, step)
        return CGammaGrid(cs, self.gamma, self.at(cs), "none",
                          None if self.sigma is None else self.at(cs, self.sigma))

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
    """Gamma angles: every 2.5 deg, and every 0.5 deg within three half-widths of a narrow
    beam (half width below 15 deg) so its peak and flanks are resolved."""
    g = np.arange(0.0, 180.0 + 1e-9, 2.5)
    if peak_half_width_deg is not None and peak_half_width_deg < 15.0:
        fine = np.arange(0.0, min(180.0, 3.0 * max(peak_half_width_deg, 1.0)) + 1e-9, 0.5)
        g = np.union1d(g, fine)
    return g


def _half_width(intensity_map: np.ndarray, up_axis: str) -> float | None:
    """Half-angle (deg) from the peak direction to where intensity halves along nadir cuts."""
    gam = np.arange(0.0, 180.0 + 1e-9, 0.25)
    d = frame.directions(np.zeros_like(gam), gam, up_axis)
    prof = sample_map(intensity_map, d)
    k = int(np.argmax(prof))
    below = np.nonzero(prof[k:] < 0.5 * prof[k])[0]
    return float(gam[k + below[0]] - gam[k]) if below.size else None


def resample(intensity_map: np.ndarray, up_axis: str, flux: float | None = None,
             c_step: float = 5.0, gammas: np.ndarray | None = None) -> CGammaGrid:
    """The full C-gamma grid (C every ``c_step`` deg) of a cube map (cd), flux-preserving.

    ``flux`` (lm) defaults to the map's own integral over the sphere.
    """
    res = intensity_map.shape[1]
    if flux is None:
        flux = float((intensity_map * texel_solid_angles(res)).sum())
    if gammas is None:
        gammas = default_gammas(_half_width(intensity_map, up_axis))
    cs = np.arange(0.0, 360.0 - 1e-9, c_step)
    cc, gg = np.meshgrid(cs, gammas, indexing="ij")
    d = frame.directions(cc, gg, up_axis).reshape(-1, 3)
    cd = np.maximum(sample_map(intensity_map, d), 0.0).reshape(cc.shape)
    grid = CGammaGrid(cs, np.asarray(gammas, dtype=np.float64), cd, "none")
    got = grid.flux()
    return replace(grid, candela=cd * (flux / got)) if got > 0 else grid


def _mirror_error(grid: CGammaGrid, mirrored_c: np.ndarray) -> float:
    """Relative RMS difference, weighted by zone solid angle, between the grid and itself
    looked up at mirrored C angles."""
    other = grid.at(mirrored_c)
    w = np.abs(np.diff(np.cos(np.radians(_midpoint_edges(grid.gamma, 0.0, 180.0)))))[None, :]
    num = (w * (grid.candela - other) ** 2).sum()
    den = (w * grid.candela ** 2).sum()
    return float(np.sqrt(num / den)) if den > 0 else 0.0


def symmetry_errors(grid: CGammaGrid) -> dict[str, float]:
    """How far the full grid is from each symmetry (relative RMS difference)."""
    c = grid.c
    mean = np.repeat(grid.candela.mean(axis=0, keepdims=True), len(c), axis=0)
    w = np.abs(np.diff(np.cos(np.radians(_midpoint_edges(grid.gamma, 0.0, 180.0)))))[None, :]
    den = (w * grid.candela ** 2).sum()
    rot = float(np.sqrt((w * (grid.candela - mean) ** 2).sum() / den)) if den > 0 else 0.0
    e0 = _mirror_error(grid, 360.0 - c)
    e90 = _mirror_error(grid, 180.0 - c)
    return {"rotational": rot, "C0-C180": e0, "C90-C270": e90, "quadrant": max(e0, e90)}


def apply_symmetry(grid: CGammaGrid, tolerance: float) -> CGammaGrid:
    """The reduced grid of the strongest symmetry the data holds within ``tolerance``
    (relative RMS), averaged over the mirrored parts; the full grid when none holds."""
    errs = symmetry_errors(grid)
    for name in ("rotational", "quadrant", "C0-C180", "C90-C270"):
        if errs[name] <= tolerance:
            return _reduce(grid, name)
    lo, hi = SYMMETRIES["none"]
    c = np.append(grid.c, 360.0)
    return CGammaGrid(c, grid.gamma, np.vstack([grid.candela, grid.candela[:1]]), "none")


def _reduce(grid: CGammaGrid, name: str) -> CGammaGrid:
    c = grid.c
    if name == "rotational":
        return CGammaGrid(np.array([0.0]), grid.gamma, grid.candela.mean(axis=0, keepdims=True),
                          name)
    mirrors = {"C0-C180": [360.0 - c], "C90-C270": [180.0 - c],
               "quadrant": [360.0 - c, 180.0 - c, 180.0 + c]}[name]
    avg = grid.candela.copy()
    for m in mirrors:
        avg += grid.at(m)
    avg /= 1 + len(mirrors)
    lo, hi = SYMMETRIES[name]
    step = _c_step(c)
    keep_c = np.arange(lo, hi + 1e-9, step)
    full = CGammaGrid(c, grid.gamma, avg, "none")
    return CGammaGrid(keep_c, grid.gamma, full.at(keep_c), name)
