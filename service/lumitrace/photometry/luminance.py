"""Luminance of the luminous opening: intensity over the projected luminous area (cd/m^2),
the table a datasheet lists (C every 15 deg, gamma 45 to 85 deg) with standard errors, and
the limits of EN 12464-1 for work at display screens stated against it.

The projected area seen from (C, gamma) is the flat face's area times |cos gamma| plus the
sides' (height times the opening's extent across the view) times sin gamma, the model of
the EULUMDAT luminous dimensions: length along C0, width along C90, a round opening an
ellipse inscribed in them. The errors are the intensities' photon noise and the measured
opening's (its dimensions' standard errors), added in quadrature; a declared opening is
exact.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .grid import CGammaGrid

#: The table's C planes and gamma angles (deg).
TABLE_C = np.arange(0.0, 360.0 - 1e-9, 15.0)
TABLE_GAMMA = np.arange(45.0, 85.0 + 1e-9, 5.0)
#: EN 12464-1 (2011, table 4; kept in 2021): mean luminance limits (cd/m^2) of luminaires
#: that may be reflected in a display screen, at gamma 65 deg and above all round, for
#: screens of high state luminance above 200 cd/m^2 ("high") and at most 200 ("low").
SCREEN_GAMMA = (65.0, 85.0)
SCREEN_LIMITS = {"high": 3000.0, "low": 1500.0}


def projected_area(opening, c_deg, gamma_deg) -> np.ndarray:
    """Luminous area (m^2) seen from directions (C, gamma) in degrees (broadcast): the flat
    face's ``opening.area`` times |cos gamma| plus the sides' times sin gamma."""
    c, g = np.radians(np.asarray(c_deg, np.float64)), np.radians(np.asarray(gamma_deg,
                                                                            np.float64))
    length, width, height = opening.length, opening.width, opening.height
    if opening.round:  # an ellipse's extent across the view
        across = 2.0 * np.sqrt((0.5 * length * np.sin(c)) ** 2 + (0.5 * width * np.cos(c)) ** 2)
    else:  # the faces normal to C0 (width wide) and to C90 (length wide)
        across = width * np.abs(np.cos(c)) + length * np.abs(np.sin(c))
    return opening.area * np.abs(np.cos(g)) + height * across * np.sin(g)


def projected_area_error(opening, c_deg, gamma_deg) -> np.ndarray:
    """Standard error (m^2) of :func:`projected_area` from the opening's dimensions'
    standard errors (``opening.error``: length, width, height), each independent."""
    base = projected_area(opening, c_deg, gamma_deg)
    errors = getattr(opening, "error", (0.0, 0.0, 0.0))
    var = np.zeros_like(base)
    for name, e in zip(("length", "width", "height"), errors):
        if e:
            moved = replace(opening, **{name: getattr(opening, name) + e})
            var = var + (projected_area(moved, c_deg, gamma_deg) - base) ** 2
    return np.sqrt(var)


def taps(grid: CGammaGrid, c_deg, gamma_deg) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear interpolation of ``grid.full()`` at points (C, gamma) (deg, flat arrays):
    (indices into the full grid's flattened values, weights), each (points, 4). Linear
    across C planes (all round) and gammas, as :meth:`CGammaGrid.at` is across planes."""
    full_c = np.arange(0.0, 360.0 - 1e-9, _step(grid))
    n_c, gam = len(full_c), grid.gamma
    c = np.mod(np.asarray(c_deg, np.float64).ravel(), 360.0)
    g = np.clip(np.asarray(gamma_deg, np.float64).ravel(), gam[0], gam[-1])
    step = 360.0 / n_c
    i0 = np.floor(c / step).astype(np.int64) % n_c
    tc = c / step - np.floor(c / step)
    i1 = (i0 + 1) % n_c
    j0 = np.clip(np.searchsorted(gam, g, side="right") - 1, 0, len(gam) - 2)
    tg = (g - gam[j0]) / (gam[j0 + 1] - gam[j0])
    ng = len(gam)
    idx = np.stack([i0 * ng + j0, i0 * ng + j0 + 1, i1 * ng + j0, i1 * ng + j0 + 1], axis=1)
    w = np.stack([(1 - tc) * (1 - tg), (1 - tc) * tg, tc * (1 - tg), tc * tg], axis=1)
    return idx, w


def _step(grid: CGammaGrid) -> float:
    d = np.diff(grid.c)
    return float(d.min()) if d.size else 5.0


def sample(grid: CGammaGrid, c_deg, gamma_deg, sigma: bool = False) -> np.ndarray:
    """Intensity (cd) of ``grid`` at points (C, gamma) (deg), or with ``sigma`` its standard
    error (the taps' errors added in quadrature, the cells being independent)."""
    full = grid.full()
    idx, w = taps(grid, c_deg, gamma_deg)
    if sigma:
        return np.sqrt(((full.sigma.ravel()[idx] * w) ** 2).sum(axis=1))
    return (full.candela.ravel()[idx] * w).sum(axis=1)


@dataclass(frozen=True)
class LuminanceTable:
    """Luminance (cd/m^2) at ``c`` by ``gamma`` (deg) with standard errors, and the largest
    luminance at the screen-work angles (every plane of the grid, gamma 65 to 85 deg)."""

    c: np.ndarray
    gamma: np.ndarray
    luminance: np.ndarray
    sigma: np.ndarray
    screen_max: float
    screen_max_error: float
    screen_max_c: float
    screen_max_gamma: float

    def as_dict(self) -> dict:
        """The record's fields: the table, the screen-work maximum and the limits met."""
        ok = {k: bool(self.screen_max <= v) for k, v in SCREEN_LIMITS.items()}
        return {"luminance_table": {"c_deg": self.c.tolist(), "gamma_deg": self.gamma.tolist(),
                                    "cd_per_m2": _rows(self.luminance),
                                    "error": _rows(self.sigma)},
                "luminance_screen_max": self.screen_max,
                "luminance_screen_max_error": self.screen_max_error,
                "luminance_screen_max_c": self.screen_max_c,
                "luminance_screen_max_gamma": self.screen_max_gamma,
                "luminance_screen_limits": {
                    "high_state_above_200": {"limit": SCREEN_LIMITS["high"], "met": ok["high"]},
                    "high_state_200_or_less": {"limit": SCREEN_LIMITS["low"], "met": ok["low"]}}}


def _rows(a: np.ndarray) -> list:
    return [[float(v) if np.isfinite(v) else None for v in row] for row in a]


def luminance_table(grid: CGammaGrid, opening, c=TABLE_C, gamma=TABLE_GAMMA
                    ) -> LuminanceTable:
    """The luminance table of ``grid`` (cd, with sigma) seen over ``opening`` (a
    :class:`~lumitrace.photometry.distribution.LuminousOpening`) at planes ``c`` and
    gammas ``gamma`` (deg), and the screen-work maximum over the grid's own points."""
    cc, gg = np.meshgrid(np.asarray(c, np.float64), np.asarray(gamma, np.float64),
                         indexing="ij")
    area = projected_area(opening, cc, gg)
    area_rel = projected_area_error(opening, cc, gg)
    with np.errstate(divide="ignore", invalid="ignore"):
        area_rel = area_rel / area
        lum = sample(grid, cc, gg).reshape(cc.shape) / area
        sig = np.hypot(sample(grid, cc, gg, sigma=True).reshape(cc.shape) / area,
                       lum * area_rel)
    full = grid.full()
    keep = (full.gamma >= SCREEN_GAMMA[0] - 1e-9) & (full.gamma <= SCREEN_GAMMA[1] + 1e-9)
    fc, fg = np.meshgrid(full.c, full.gamma[keep], indexing="ij")
    with np.errstate(divide="ignore", invalid="ignore"):
        screen_area = projected_area(opening, fc, fg)
        screen = full.candela[:, keep] / screen_area
        screen_sig = np.hypot(full.sigma[:, keep] / screen_area, screen * projected_area_error(
            opening, fc, fg) / screen_area)
    screen = np.where(np.isfinite(screen), screen, 0.0)
    k = np.unravel_index(int(np.argmax(screen)), screen.shape)
    return LuminanceTable(cc[:, 0], gg[0], lum, sig, float(screen[k]), float(screen_sig[k]),
                          float(fc[k]), float(fg[k]))
