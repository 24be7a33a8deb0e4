"""Figures derived from a luminous intensity distribution: fluxes, ratios, angles, CIE code.

CIE flux code (CIE 52): N1, N2, N3 are the shares of the downward flux within 41.4, 60
and 75.5 degrees of nadir, N4 the downward share of the luminaire flux, N5 the light
output ratio, all in percent.

All are computed on a fine C-gamma grid (2 deg by 0.25 deg) resampled from the map, so zone
boundaries such as the CIE flux code's 41.4, 60 and 75.5 degrees are resolved.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .grid import CGammaGrid, resample

#: Cone half-angles (deg) of the CIE flux code: solid angles pi/2, pi, 3pi/2 and 2pi sr.
CIE_ZONES = (41.4, 60.0, 75.5, 90.0)


@dataclass(frozen=True)
class PhotometricFigures:
    """What a datasheet lists (lm, %, cd, degrees)."""

    luminous_flux: float
    lamp_flux: float
    light_output_ratio: float
    downward_flux_fraction: float
    upward_flux_fraction: float
    peak_intensity: float
    peak_c: float
    peak_gamma: float
    beam_angle_c0_c180: float | None
    beam_angle_c90_c270: float | None
    field_angle_c0_c180: float | None
    field_angle_c90_c270: float | None
    cie_flux_code: str

    def as_dict(self) -> dict:
        return asdict(self)


def zonal_flux(grid: CGammaGrid, gamma_deg: float) -> float:
    """Flux (lm) inside the cone gamma < ``gamma_deg`` about nadir (exact zone edges)."""
    g = grid.full()
    gam = np.union1d(g.gamma, [gamma_deg])
    gam = gam[gam <= gamma_deg + 1e-12]
    rows = np.array([np.interp(gam, g.gamma, row) for row in g.candela])
    # trapezoid in gamma of I(gamma) sin(gamma), sectors in C
    s = np.sin(np.radians(gam))
    per_c = np.trapezoid(rows * s[None, :], np.radians(gam), axis=1)
    dc = 2.0 * np.pi / len(g.c)
    return float(per_c.sum() * dc)


def _plane_profile(grid: CGammaGrid, c_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Intensity across a vertical plane: angle from nadir, negative on the C+180 side."""
    a = grid.at(np.array([c_deg]))[0]
    b = grid.at(np.array([c_deg + 180.0]))[0]
    ang = np.concatenate([-grid.gamma[::-1], grid.gamma[1:]])
    return ang, np.concatenate([b[::-1], a[1:]])


def spread_angle(grid: CGammaGrid, c_deg: float, fraction: float) -> float | None:
    """Full angle (deg) between the directions of the plane through ``c_deg`` where the
    intensity falls to ``fraction`` of the plane's maximum, either side of the maximum."""
    ang, prof = _plane_profile(grid, c_deg)
    k = int(np.argmax(prof))
    level = fraction * prof[k]
    if prof[k] <= 0:
        return None

    def crossing(idx):
        for i0, i1 in zip(idx[:-1], idx[1:]):
            if prof[i1] < level <= prof[i0]:
                t = (prof[i0] - level) / (prof[i0] - prof[i1])
                return ang[i0] + t * (ang[i1] - ang[i0])
        return None

    right = crossing(list(range(k, len(ang))))
    left = crossing(list(range(k, -1, -1)))
    if right is None or left is None:
        return None
    return float(right - left)


def figures(intensity_map: np.ndarray, up_axis: str, escaped_flux: float,
            lamp_flux: float) -> PhotometricFigures:
    """Derived figures of a cube-map distribution (cd) whose integral is ``escaped_flux``."""
    fine = resample(intensity_map, up_axis, escaped_flux, c_step=2.0,
                    gammas=np.arange(0.0, 180.0 + 1e-9, 0.25))
    total = fine.flux()
    down = zonal_flux(fine, 90.0)
    zones = [zonal_flux(fine, z) for z in CIE_ZONES[:3]]
    n = [100.0 * z / down if down > 0 else 0.0 for z in zones]
    n4 = 100.0 * down / total if total > 0 else 0.0  # downward flux fraction
    n5 = 100.0 * total / lamp_flux if lamp_flux > 0 else 0.0  # light output ratio
    code = " ".join(str(int(round(v))) for v in (*n, n4, n5))
    peak, pc, pg = fine.peak
    return PhotometricFigures(
        luminous_flux=total, lamp_flux=lamp_flux,
        light_output_ratio=total / lamp_flux if lamp_flux > 0 else math.nan,
        downward_flux_fraction=down / total if total > 0 else 0.0,
        upward_flux_fraction=1.0 - down / total if total > 0 else 0.0,
        peak_intensity=peak, peak_c=pc, peak_gamma=pg,
        beam_angle_c0_c180=spread_angle(fine, 0.0, 0.5),
        beam_angle_c90_c270=spread_angle(fine, 90.0, 0.5),
        field_angle_c0_c180=spread_angle(fine, 0.0, 0.1),
        field_angle_c90_c270=spread_angle(fine, 90.0, 0.1),
        cie_flux_code=code)
