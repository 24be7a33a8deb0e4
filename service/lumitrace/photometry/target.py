"""A target photometric file (IES LM-63 or EULUMDAT) read as a reference to compare a design
with: its C-gamma grid, lamp flux and luminous opening, and its figures as a photometric
reader computes them from the grid it holds (no counts, no standard errors: a target states
none).

Flux by zonal integration of the grid; the peak is its largest value; beam and field angles
are the outermost crossings of its plane profiles (linear in gamma, on a 0.5 deg raster) with
half (a tenth) of the peak where the peak lies in the plane, else of the plane's own largest
value (:func:`~lumitrace.photometry.quantities.outermost_crossings`, the plane rule of
:mod:`.quantities`); UGR 4H x 8H 70/50/20 from the file's luminous opening (:mod:`.ugr`).
A noisy grid's largest value is a spike and its angles are read off it, as any reader of
the file would."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import PurePath

import numpy as np

from ..errors import LumitraceError
from .distribution import LuminousOpening
from .eulumdat import parse_ldt
from .grid import CGammaGrid
from .lm63 import parse_ies
from .peak import Peak
from .quantities import PROFILE_GAMMAS, _in_plane, outermost_crossings
from .ugr import ugr_table

#: Feet in a metre's units (IES ``units`` 1: feet, 2: metres).
FOOT = 0.3048


@dataclass(frozen=True)
class Target:
    """A photometric file's distribution: ``grid`` (cd), ``lamp_lumens`` (None for
    absolute photometry), its ``opening`` (m) and format (``ies`` or ``ldt``)."""

    name: str
    format: str
    grid: CGammaGrid
    lamp_lumens: float | None
    opening: LuminousOpening


def read_target(name: str, text: str) -> Target:
    """Parse a photometric file's ``text`` (IES by its first line or a ``.ies`` name,
    EULUMDAT otherwise). Raises :class:`LumitraceError` naming the file and what is
    wrong; nothing else for any text."""
    where = PurePath(name).name or "photometric file"
    head = text.lstrip("\ufeff").lstrip()[:20].upper()
    is_ies = head.startswith("IES") or name.lower().endswith(".ies") or \
        head.startswith("TILT")
    try:
        if is_ies:
            ies = parse_ies(text, where)
            grid = ies.grid()
            lumens = ies.lumens_per_lamp * ies.lamps if ies.lumens_per_lamp > 0 else None
            unit = FOOT if ies.units == 1 else 1.0
            w, ln = abs(ies.width) * unit, abs(ies.length) * unit
            opening = LuminousOpening(ln, w, abs(ies.height) * unit,
                                      round=ies.width < 0 or ies.length < 0)
            fmt = "ies"
        else:
            ldt = parse_ldt(text, where)
            grid = ldt.grid
            lumens = ldt.lamp_flux if ldt.lamp_flux > 0 else None
            d = ldt.dims_mm
            ln, w = d["lum_length"] / 1000.0, d["lum_width"] / 1000.0
            opening = LuminousOpening(ln, w if w > 0 else ln, d.get("lum_height", 0.0) / 1000.0,
                                      round=w <= 0)
            fmt = "ldt"
    except LumitraceError:
        raise
    except (ValueError, IndexError, KeyError, TypeError, ZeroDivisionError,
            OverflowError) as exc:
        raise LumitraceError(f"cannot read it as {'IES' if is_ies else 'EULUMDAT'}: {exc}",
                             where) from None
    _check(grid, where)
    return Target(where, fmt, grid, lumens, opening)


def _check(grid: CGammaGrid, where: str) -> None:
    """Refuse a grid no comparison can use (one clear error)."""
    cd, g, c = grid.candela, grid.gamma, grid.c
    # (a slightly negative value is kept: unbiased point values of a noisy estimate, ours
    # among them, may fall below zero where next to no light leaves)
    if cd.size == 0 or not np.all(np.isfinite(cd)):
        raise LumitraceError("its candela values must be finite numbers", where)
    if not np.all(np.isfinite(g)) or g.min() < 0 or g.max() > 180 or np.any(np.diff(g) <= 0):
        raise LumitraceError("its gamma angles must rise within 0-180 deg", where)
    if not np.all(np.isfinite(c)) or np.any(np.diff(c) <= 0):
        raise LumitraceError("its C angles must rise", where)
    if not cd.max() > 0:
        raise LumitraceError("it emits nothing", where)


def target_figures(t: Target) -> dict:
    """The figures of :class:`~lumitrace.photometry.quantities.PhotometricFigures` that a
    file determines (flux, light output ratio, peak, beam and field angles, UGR 4H x 8H
    70/50/20 crosswise and endwise), each ``*_error`` 0."""
    grid = t.grid
    flux = grid.flux()
    value, c_peak, g_peak = grid.peak
    peak = Peak(value, 0.0, c_peak, g_peak)
    fine = replace(grid, gamma=PROFILE_GAMMAS, candela=_in_gamma(grid, PROFILE_GAMMAS),
                   sigma=None)
    out = {"luminous_flux": flux, "luminous_flux_error": 0.0, "lamp_flux": t.lamp_lumens,
           "light_output_ratio": flux / t.lamp_lumens if t.lamp_lumens else None,
           "light_output_ratio_error": 0.0 if t.lamp_lumens else None,
           "peak_intensity": value, "peak_intensity_error": 0.0, "peak_c": c_peak,
           "peak_gamma": g_peak}
    for c, name in ((0.0, "c0_c180"), (90.0, "c90_c270")):
        ang, prof = _profile(fine, c)
        top = value if _in_plane(peak, c, grid.symmetry) else float(prof.max())
        for fraction, kind in ((0.5, "beam"), (0.1, "field")):
            left, right = outermost_crossings(ang, prof[None], np.array([fraction * top]))
            width = float(right[0] - left[0])
            ok = math.isfinite(width)
            out[f"{kind}_angle_{name}"] = width if ok else None
            out[f"{kind}_angle_{name}_error"] = 0.0 if ok else None
    out.update(target_ugr(t))
    return out


def target_ugr(t: Target) -> dict:
    """UGR 4H x 8H 70/50/20 of the file (None where its opening has no area)."""
    none = {"ugr_4h8h_70_50_20": None, "ugr_4h8h_70_50_20_error": None,
            "ugr_4h8h_70_50_20_endwise": None, "ugr_4h8h_70_50_20_endwise_error": None}
    o = t.opening
    if not (o.area > 0 or o.height > 0):
        return none
    grid = replace(t.grid, sigma=np.zeros_like(t.grid.candela))
    table = ugr_table(grid, o)
    cross, end = table.catalogue(), table.catalogue(endwise=True)
    finite = lambda v: v if math.isfinite(v) else None  # noqa: E731
    return {"ugr_4h8h_70_50_20": finite(cross[0]),
            "ugr_4h8h_70_50_20_error": 0.0 if finite(cross[0]) is not None else None,
            "ugr_4h8h_70_50_20_endwise": finite(end[0]),
            "ugr_4h8h_70_50_20_endwise_error": 0.0 if finite(end[0]) is not None else None}


def _in_gamma(grid: CGammaGrid, gammas: np.ndarray) -> np.ndarray:
    """The grid's planes at ``gammas`` (deg), linear in gamma, 0 beyond its range."""
    return np.stack([np.interp(gammas, grid.gamma, row, left=0.0, right=0.0)
                     for row in grid.candela])


def _profile(grid: CGammaGrid, c: float) -> tuple[np.ndarray, np.ndarray]:
    """Angles (deg from nadir, negative toward C + 180) and intensities across the vertical
    plane through ``c``."""
    a = grid.at(np.array([c]))[0]
    b = grid.at(np.array([c + 180.0]))[0]
    return np.concatenate([-grid.gamma[::-1], grid.gamma[1:]]), np.concatenate([b[::-1], a[1:]])
