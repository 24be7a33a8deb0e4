"""Illuminance from the measured grid in the far field (inverse-square law, the luminaire a
point at its photometric centre): the cone diagram of spot and downlight datasheets (centre
illuminance and beam diameter at mounting distances) and isolux values on a plane below
the luminaire, each with its standard error.

Centre illuminance at distance d is E = I(0) / d^2 (lx), I(0) the nadir value (the mean
over its polar cap) ; the beam diameter is 2 d tan(beam angle / 2) in each plane, its error
from the beam angle's. On a plane h below, E(x, y) = I(C, gamma) cos^3(gamma) / h^2, the
values given for h = 1 m with x, y in multiples of h (at height h: E / h^2 at x h, y h).
The far field holds where d is large against the luminous opening (five times its size is
the usual rule); nearer, these values are not the illuminance.
"""
from __future__ import annotations

import math

import numpy as np

from .grid import CGammaGrid
from .luminance import sample

#: Mounting distances (m) of the cone diagram.
DISTANCES = (1.0, 2.0, 3.0, 4.0, 5.0)
#: Isolux plane: x and y (multiples of the height) from -ISOLUX_EXTENT to +ISOLUX_EXTENT.
ISOLUX_EXTENT = 3.0
ISOLUX_STEP = 0.25


def _diameters(angle, error, distances) -> tuple[list, list]:
    if angle is None:
        return [None] * len(distances), [None] * len(distances)
    half = math.radians(angle) / 2.0
    d = [2.0 * x * math.tan(half) for x in distances]
    e = [None if error is None else x / math.cos(half) ** 2 * math.radians(error)
         for x in distances]
    return d, e


def cone_diagram(grid: CGammaGrid, figures, distances=DISTANCES) -> dict:
    """Centre illuminance (lx) and beam diameters (m) with errors at ``distances`` (m),
    from ``grid`` (cd, with sigma) and the beam angles of ``figures``
    (:class:`~lumitrace.photometry.quantities.PhotometricFigures`)."""
    i0 = float(grid.candela[0, 0])
    s0 = float(grid.sigma[0, 0]) if grid.sigma is not None else None
    d0, e0 = _diameters(figures.beam_angle_c0_c180, figures.beam_angle_c0_c180_error,
                        distances)
    d90, e90 = _diameters(figures.beam_angle_c90_c270, figures.beam_angle_c90_c270_error,
                          distances)
    return {"distance_m": list(distances),
            "centre_lux": [i0 / d ** 2 for d in distances],
            "centre_lux_error": [None if s0 is None else s0 / d ** 2 for d in distances],
            "beam_diameter_c0_c180_m": d0, "beam_diameter_c0_c180_m_error": e0,
            "beam_diameter_c90_c270_m": d90, "beam_diameter_c90_c270_m_error": e90}


def isolux(grid: CGammaGrid, extent: float = ISOLUX_EXTENT, step: float = ISOLUX_STEP
           ) -> dict:
    """Illuminance (lx) and its error on the plane 1 m below the luminaire at x (along C0)
    and y (along C90) from -``extent`` to ``extent`` m every ``step`` m."""
    n = int(round(extent / step))
    axis = np.arange(-n, n + 1) * step
    x, y = np.meshgrid(axis, axis, indexing="xy")  # rows along y, columns along x
    c = np.degrees(np.arctan2(y, x)) % 360.0
    gamma = np.degrees(np.arctan(np.hypot(x, y)))
    k = np.cos(np.radians(gamma)) ** 3
    e = (sample(grid, c, gamma) * k.ravel()).reshape(x.shape)
    s = (sample(grid, c, gamma, sigma=True) * k.ravel()).reshape(x.shape)
    return {"height_m": 1.0, "x_m": axis.tolist(), "y_m": axis.tolist(),
            "lux": np.round(e, 6).tolist(), "lux_error": np.round(s, 6).tolist()}
