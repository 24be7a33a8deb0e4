"""The luminous flux a lighting program computes from a photometric file: its values read
by a third-party reader as intensities at the listed angles, integrated with the trapezoidal
rule in gamma (of I sin gamma) and in C, as AGi32 and DIALux do. Written apart from
lumitrace: it shares no code with the writers it checks."""
from __future__ import annotations

import math

import numpy as np


def unfolded(c: np.ndarray, table: np.ndarray, isym: int) -> tuple[np.ndarray, np.ndarray]:
    """Planes all round (C 0 .. 360 deg, the last repeating the first) from a file's
    stored planes ``c`` (deg) and ``table`` (planes, gammas), unfolding EULUMDAT's
    symmetry indicator ``isym`` (0 none, 1 rotational, 2 C0-C180, 3 C90-C270, 4 quadrant)."""
    c = np.asarray(c, np.float64)
    table = np.asarray(table, np.float64)
    if isym == 1:
        cs = np.arange(0.0, 360.0 + 1e-9, 5.0)
        return cs, np.repeat(table[:1], len(cs), axis=0)
    step = float(np.min(np.diff(np.unique(c)))) if len(np.unique(c)) > 1 else 5.0
    cs = np.arange(0.0, 360.0 + 1e-9, step)
    folded = {0: cs, 2: np.where(cs > 180, 360 - cs, cs),
              3: np.where(cs < 90, 180 - cs, np.where(cs > 270, 540 - cs, cs)),
              4: np.where(cs > 180, 360 - cs, cs)}[isym]
    if isym == 4:
        folded = np.where(folded > 90, 180 - folded, folded)
    rows = [int(np.argmin(np.abs(c - f))) for f in folded % 360.0]
    assert np.allclose(c[rows], folded % 360.0, atol=1e-6) or isym == 0
    return cs, table[rows]


def trapezoidal_flux(c: np.ndarray, gamma: np.ndarray, cd: np.ndarray) -> float:
    """Flux (lm) of intensities ``cd`` (C planes all round, the last at 360 deg; gammas)
    as point values: trapezoidal in gamma of I sin gamma, then in C."""
    g = np.radians(np.asarray(gamma, np.float64))
    per_plane = np.trapezoid(np.asarray(cd) * np.sin(g)[None, :], g, axis=1)
    return float(np.trapezoid(per_plane, np.radians(c)))


def ldt_flux(ldt) -> tuple[float, float]:
    """(the flux a point-value reader integrates from a pyldt ``Ldt``, the flux it
    declares: light output ratio times the lamps' flux), lm."""
    h = ldt.header
    lamp = float(sum(h.num_lamps[i] * h.lamp_flux[i] for i in range(len(h.lamp_flux)))) \
        if isinstance(h.lamp_flux, (list, tuple)) else float(h.lamp_flux)
    lamp = abs(lamp)
    c = np.asarray(h.c_angles, np.float64)
    stored = np.asarray(ldt.intensities, np.float64)
    if stored.ndim == 1:
        stored = stored[None, :]
    cs, table = unfolded(c[:len(stored)] if h.isym else c, stored, int(h.isym))
    cd = table * h.conv_factor * lamp / 1000.0
    return trapezoidal_flux(cs, h.g_angles, cd), float(h.lorl) / 100.0 * lamp


def stated_error(flux_error: float, flux: float) -> float:
    """The relative error a flux check allows: max(0.3 %, two stated errors)."""
    return max(0.003, 2.0 * flux_error / flux) if flux > 0 else math.inf
