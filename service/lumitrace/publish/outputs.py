"""Writing a traced result: the intensity EXR first, then the result layer that names it.

File names follow the stage: for ``NAME.usda`` the outputs are ``NAME.intensity.exr`` (in
the output folder) and ``NAME.lumitrace.usda`` (beside the stage, sublayered into it once).
Every file is written atomically, textures before the layer that references them.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from ..film.cubemap import texel_directions
from ..filenames import stage_name
from ..run.session import TraceResult


@dataclass(frozen=True)
class ResultFigures:
    """The numbers a result is summarised by (lm, cd, s)."""

    photons: int
    iterations: int
    seconds: float
    emitted_lm: float
    escaped_lm: float
    absorbed_lm: float
    cut_lm: float
    light_output_ratio: float
    peak_cd: float
    peak_direction: tuple[float, float, float]
    relative_error: float
    converged: bool
    photons_per_second: float
    segments_per_second: float


def input_hash(result: TraceResult) -> str:
    """Hash of the scene content and the settings that shape the map."""
    s = result.settings
    h = hashlib.sha256(result.scene.content_hash().encode())
    h.update(json.dumps({"resolution": s.resolution, "seed": s.seed, "threshold": s.threshold,
                         "max_depth": s.max_depth}, sort_keys=True).encode())
    return h.hexdigest()


def figures(result: TraceResult) -> ResultFigures:
    """Summary figures of a result, from the map the user sees (``Y``, cd)."""
    acc = result.accumulator
    f = acc.fluxes()
    shown = result.estimate.filtered
    k = int(np.argmax(shown))
    peak_dir = texel_directions(acc.resolution).reshape(-1, 3)[k]
    secs = max(result.seconds, 1e-9)
    return ResultFigures(
        photons=acc.photons, iterations=result.iterations, seconds=result.seconds,
        emitted_lm=f["emitted"], escaped_lm=f["escaped"], absorbed_lm=f["absorbed"],
        cut_lm=f["cut"], light_output_ratio=f["escaped"] / f["emitted"] if f["emitted"] else 0.0,
        peak_cd=float(shown.ravel()[k]), peak_direction=tuple(float(x) for x in peak_dir),
        relative_error=result.relative_error, converged=result.converged,
        photons_per_second=acc.photons / secs, segments_per_second=acc.segments / secs)


def photometric_light(scene, photometry: dict, layer_dir: Path) -> dict:
    """The UsdLux light standing in for the luminaire: an IES-shaped disk the size of its
    luminous opening (equal area), at the opening's centre, with the luminaire's flux."""
    from ..photometry import frame

    opening = photometry["opening"]
    _, _, up = frame.axes(scene.up_axis)
    mpu = scene.meters_per_unit
    tri = np.asarray(scene.triangles).reshape(-1, 3)
    if tri.size:
        lo, hi = tri.min(axis=0), tri.max(axis=0)
        centre = 0.5 * (lo + hi)
        if photometry["figures"].downward_flux_fraction > 0.5:  # opening at the bottom
            centre = centre - up * (0.5 * float((hi - lo) @ up))
    else:
        centre = np.mean([np.asarray(e.to_world)[:3, 3] for e in scene.emitters], axis=0)
    radius = float(np.sqrt(max(opening.length * opening.width, 1e-12) / np.pi))
    return {"ies": os.path.relpath(photometry["ies"], layer_dir),
            "flux": photometry["figures"].luminous_flux, "radius": radius / mpu,
            "position": tuple(float(x) / mpu for x in centre), "up_axis": scene.up_axis,
            "emitters": [e.path for e in scene.emitters if "[" not in e.path]}


def write_outputs(result: TraceResult, out_dir: str | os.PathLike | None) -> dict:
    """Write the EXR and the result layer; return the paths and figures as a dict."""
    from .exr import write_intensity_exr
    from .result_layer import write_result_layer

    scene = result.scene
    stage_path = Path(scene.stage_path)
    out = Path(out_dir) if out_dir is not None else stage_path.parent
    name = stage_name(stage_path)
    exr_path = out / f"{name}.intensity.exr"
    fig = figures(result)
    est = result.estimate
    acc = result.accumulator
    digest = input_hash(result)
    meta = {
        "software": f"lumitrace {__version__}",
        "stage": stage_path.name,
        "luminaire": scene.luminaire_path,
        "units": {"Y": "cd", "raw.Y": "cd", "count": "photons",
                  "relativeError": "relative standard error of Y per texel"},
        "axes": f"stage axes, up {scene.up_axis}",
        "photons": fig.photons,
        "iterations": fig.iterations,
        "elapsedSeconds": fig.seconds,
        "relativeError": fig.relative_error,
        "rawRelativeError": est.raw_error,
        "filteredRelativeError": est.filtered_error,
        "errorDefinition": "estimated relative RMS error of Y over the sphere: "
                           "sqrt(sum(dOmega (Y - Y_true)^2) / sum(dOmega Y_true^2))",
        "converged": fig.converged,
        "targetError": result.settings.target_error,
        "threshold": result.settings.threshold,
        "resolution": acc.resolution,
        "seed": result.settings.seed,
        "inputHash": digest,
        "emittedFlux": fig.emitted_lm,
        "luminousFlux": fig.escaped_lm,
        "absorbedFlux": fig.absorbed_lm,
        "cutFlux": fig.cut_lm,
        "lightOutputRatio": fig.light_output_ratio,
        "emitters": [{"path": t.path, "flux": t.flux, "photons": t.photons}
                     for t in acc.emitters],
    }
    from ..photometry.files import figures_for_layer, write_photometry

    photometry = write_photometry(scene, est.filtered, fig.escaped_lm, out, name,
                                  result.relative_error)
    pfig = photometry["figures"]
    meta["photometry"] = {**pfig.as_dict(), "symmetry": photometry["grid"].symmetry}
    channels = {"Y": est.filtered, "raw.Y": est.raw, "count": acc.counts().astype(np.float64),
                "relativeError": np.minimum(est.texel_error, 1e30)}
    write_intensity_exr(exr_path, channels, meta)
    layer_dir = stage_path.parent
    layer_path = write_result_layer(stage_path, scene.luminaire_path, {
        "intensityMap": os.path.relpath(exr_path, layer_dir),
        "iesFile": os.path.relpath(photometry["ies"], layer_dir),
        "ldtFile": os.path.relpath(photometry["ldt"], layer_dir),
        "polarDiagram": os.path.relpath(photometry["polar"], layer_dir),
        "photometricSolid": os.path.relpath(photometry["solid"], layer_dir),
        **figures_for_layer(pfig),
        "photons": fig.photons,
        "iterations": fig.iterations,
        "elapsedSeconds": fig.seconds,
        "relativeError": fig.relative_error,
        "luminousFlux": fig.escaped_lm,
        "lightOutputRatio": fig.light_output_ratio,
        "threshold": float(result.settings.threshold),
        "resolution": acc.resolution,
        "seed": result.settings.seed,
        "converged": fig.converged,
        "inputHash": digest,
    }, light=photometric_light(scene, photometry, layer_dir))
    return {"intensity_map": str(exr_path), "result_layer": str(layer_path), "figures": fig,
            "ies": str(photometry["ies"]), "ldt": str(photometry["ldt"]),
            "polar_diagram": str(photometry["polar"]),
            "photometric_solid": str(photometry["solid"]),
            "photometry": pfig, "symmetry": photometry["grid"].symmetry}
