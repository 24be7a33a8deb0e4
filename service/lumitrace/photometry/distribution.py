"""The photometric description of a traced result: C-gamma grid, symmetry, figures and
the luminous opening, ready for the IES and EULUMDAT writers and the pictures."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import Scene
from . import frame
from .grid import CGammaGrid, apply_symmetry, resample
from .quantities import PhotometricFigures, figures

#: Symmetry is used where the data departs from it by less than this (relative RMS), or
#: by less than three times the map's own estimated error when that is larger.
SYMMETRY_TOLERANCE = 0.01


@dataclass(frozen=True)
class LuminousOpening:
    """Luminous dimensions (m) in the photometric frame: along C0, along C90, vertical."""

    length: float
    width: float
    height: float


def luminous_opening(scene: Scene, downward_fraction: float) -> LuminousOpening:
    """The luminaire's extent in the photometric frame: its geometry's bounding box (or its
    emitters' where it has none); height 0 for a luminaire that sends all light down
    through a horizontal opening (LM-63's flat luminous area)."""
    c0, c90, up = frame.axes(scene.up_axis)
    tri = np.asarray(scene.triangles).reshape(-1, 3)
    if tri.size == 0:
        tri = np.array([np.asarray(e.to_world)[:3, 3] for e in scene.emitters])
        spans = [_emitter_span(e) for e in scene.emitters]
        pad = max(spans) if spans else 0.0
    else:
        pad = 0.0
    ext = lambda axis: float(np.ptp(tri @ axis)) + pad  # noqa: E731
    height = 0.0 if downward_fraction > 0.99 else ext(up)
    return LuminousOpening(length=ext(c0), width=ext(c90), height=height)


def _emitter_span(e) -> float:
    """Largest size (m) of an emitter's emitting shape."""
    local = {"sphere": 2 * e.radius, "disk": 2 * e.radius, "rect": max(e.width, e.height),
             "cylinder": max(e.length, 2 * e.radius)}[e.kind]
    if e.kind == "sphere" and e.treat_as_point:
        local = 0.0
    return local * float(np.linalg.norm(np.asarray(e.to_world)[:3, :3], axis=0).max())


@dataclass(frozen=True)
class Photometry:
    """The photometric description of an intensity map: the C-gamma grid (full, and
    reduced to the symmetry the data holds), the derived figures and the luminous opening."""

    grid: CGammaGrid
    grid_full: CGammaGrid
    figures: PhotometricFigures
    opening: LuminousOpening
    lamp_flux: float


def photometry_of(scene: Scene, intensity_map: np.ndarray, escaped_flux: float,
               map_error: float = 0.0) -> Photometry:
    """Resample an intensity map (cd, cube map) onto the C-gamma grid in the photometric
    frame, detect its symmetry and derive the figures (lm, cd, deg)."""
    lamp = scene.total_flux
    grid_full = resample(intensity_map, scene.up_axis, escaped_flux)
    tol = max(SYMMETRY_TOLERANCE, 3.0 * map_error)
    grid = apply_symmetry(grid_full, tol)
    fig = figures(intensity_map, scene.up_axis, escaped_flux, lamp)
    opening = luminous_opening(scene, fig.downward_flux_fraction)
    return Photometry(grid, grid_full, fig, opening, lamp)
