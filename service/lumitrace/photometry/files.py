"""The photometric outputs of a traced result: IES and EULUMDAT files, figures, pictures."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..scene import Scene
from . import frame
from .diagrams import photometric_solid, polar_diagram
from .eulumdat import write_ldt
from .grid import CGammaGrid, apply_symmetry, resample
from .lm63 import write_ies
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


def write_photometry(scene: Scene, intensity_map: np.ndarray, escaped_flux: float,
                     out_dir: str | Path, name: str, map_error: float = 0.0) -> dict:
    """Write ``NAME.ies``, ``NAME.ldt``, ``NAME.polar.png`` and ``NAME.solid.png`` for a
    filtered intensity map (cd); return their paths, the grid and the figures."""
    out = Path(out_dir)
    lamp = scene.total_flux
    grid_full = resample(intensity_map, scene.up_axis, escaped_flux)
    tol = max(SYMMETRY_TOLERANCE, 3.0 * map_error)
    grid = apply_symmetry(grid_full, tol)
    fig = figures(intensity_map, scene.up_axis, escaped_flux, lamp)
    opening = luminous_opening(scene, fig.downward_flux_fraction)
    luminaire = scene.luminaire_path.rsplit("/", 1)[-1] or name
    keywords = {"LUMCAT": name, "LUMINAIRE": f"{luminaire} ({Path(scene.stage_path).name})",
                "LAMP": f"{len(scene.emitters)} UsdLux emitter(s), {lamp:.6g} lm",
                "FILEGENINFO": "computed by photon tracing from the USD stage; "
                               f"estimated relative RMS error {map_error:.2%}; "
                               f"symmetry {grid.symmetry}"}
    ies = write_ies(out / f"{name}.ies", grid, lamp, opening.width, opening.length,
                    opening.height, keywords)
    mm = {"length": 1000 * opening.length, "width": 1000 * opening.width,
          "height": 1000 * opening.height, "lum_length": 1000 * opening.length,
          "lum_width": 1000 * opening.width, "lum_height": 1000 * opening.height}
    ldt = write_ldt(out / f"{name}.ldt", grid, lamp, luminaire, mm,
                    fig.downward_flux_fraction, fig.light_output_ratio,
                    report=f"lumitrace {name}")
    title = f"{luminaire}: {fig.luminous_flux:.0f} lm, LOR {fig.light_output_ratio:.2f}"
    polar = polar_diagram(out / f"{name}.polar.png", grid, lamp, title)
    solid = photometric_solid(out / f"{name}.solid.png", grid, scene, title)
    return {"ies": ies, "ldt": ldt, "polar": polar, "solid": solid, "grid": grid,
            "grid_full": grid_full, "figures": fig, "opening": opening}


def figures_for_layer(fig: PhotometricFigures) -> dict:
    """Result-layer attributes of the figures (NaN for angles that do not exist)."""
    nan = lambda v: math.nan if v is None else float(v)  # noqa: E731
    return {"downwardFluxFraction": fig.downward_flux_fraction,
            "peakIntensity": fig.peak_intensity,
            "beamAngleC0": nan(fig.beam_angle_c0_c180), "beamAngleC90": nan(fig.beam_angle_c90_c270),
            "fieldAngleC0": nan(fig.field_angle_c0_c180),
            "fieldAngleC90": nan(fig.field_angle_c90_c270),
            "cieFluxCode": fig.cie_flux_code}


__all__ = ["CGammaGrid", "write_photometry", "figures_for_layer", "luminous_opening"]
