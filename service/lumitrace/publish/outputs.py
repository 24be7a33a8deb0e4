"""Writing a traced result: photometric files and the intensity EXR first, then the result
layer that names them.

File names follow the stage (:mod:`lumitrace.filenames`): for ``NAME.usda`` the outputs go
to the output folder and ``NAME.lumitrace.usda`` beside the stage, sublayered into it once.
Every file is written atomically, the files before the layer that references them.
"""
from __future__ import annotations

import importlib.util
import os
from pathlib import Path
from typing import Callable

import numpy as np

from .. import __version__
from ..digests import file_digest
from ..errors import Interrupted, OutputError, OutputWarning, warn
from ..filenames import INTENSITY_SUFFIX, LATLONG_SUFFIX, RESULT_LAYER_SUFFIX, stage_name
from ..photometry import frame
from ..film.convergence import colour_maps
from ..photometry.colour import ColourOverAngle, colour_over_angle
from ..photometry.distribution import (SYMMETRY_TOLERANCE, Photometry, files_accuracy,
                                      photometry_of)
from ..schema import SYMMETRY as LUMINAIRE_SYMMETRY
from ..photometry.measured import emitter_rings
from ..photometry.zonal import zonal_flux
from ..photometry.tables import application_figures
from ..film.result import TraceResult
from ..scene import Scene
from .exr import write_intensity_exr
from .latlong import write_latlong_texture
from .photometric import photometric_paths, write_colour_files, write_photometric_files
from .deliverables import deliverable_paths, write_deliverables
from ..schema import RESULT_FIELDS
from .record import ResultRecord, trace_figures
from .ownership import claim_outputs, ownership_record
from .result_layer import result_layer_text, write_layer_file
from .sublayer import RootEdit, reload_if_open, sublayer_into_root
from .transaction import DEFAULT_LOCK_WAIT, Transaction, locked, recover, signals_held


#: ``relativeError`` of a texel with no estimate (no photons, nothing borrowed), and the cap
#: of every texel's: a finite value that half floats, viewers and filters survive.
MAX_TEXEL_ERROR = 100.0


def photometric_light(scene: Scene, ph: Photometry, ies_path: Path, layer_dir: Path) -> dict:
    """The UsdLux light standing in for the luminaire, a child of the luminaire prim: an
    IES-shaped disk of the measured luminous opening's area (an ellipse's where it is
    round), at the opening's centre (luminaire space, stage units), with the luminaire's
    flux."""
    opening = ph.opening
    centre = np.asarray(scene.photometric_axes).T @ np.asarray(opening.centre)  # world m
    m = np.asarray(scene.luminaire_to_world) if scene.luminaire_to_world else \
        np.diag([scene.meters_per_unit] * 3 + [1.0])
    local = np.linalg.solve(m, np.append(centre, 1.0))[:3]
    scale = float(np.cbrt(abs(np.linalg.det(m[:3, :3])))) or scene.meters_per_unit
    radius = float(np.sqrt(max(opening.area, 1e-12) / np.pi))
    return {"ies": os.path.relpath(ies_path, layer_dir),
            "flux": ph.figures.luminous_flux, "radius": radius / scale,
            "position": tuple(float(x) for x in local), "up_axis": scene.up_axis,
            "emitters": [p for e in scene.emitters for p in e.light_paths if "[" not in p]}


def plotting_available() -> bool:
    """Whether the plot extra (matplotlib) is installed."""
    return importlib.util.find_spec("matplotlib") is not None


def build_record(result: TraceResult, ph: Photometry, paths: dict[str, Path],
                 col: ColourOverAngle | None = None) -> ResultRecord:
    """The result record of a traced session, its photometry, its colour over angle (None:
    the stage has no colour) and its output paths."""
    fig = ph.figures
    if result.judge_files and result.files_accuracy is None:  # judged on the grid written
        result.files_accuracy = files_accuracy(result.scene, result.accumulator, ph)
    peak_dir = frame.directions(np.array(fig.peak_c), np.array(fig.peak_gamma),
                                result.scene.up_axis, frame.luminaire_rotation(result.scene))
    o = ph.opening
    return ResultRecord({**trace_figures(result), **fig.as_dict(), "symmetry": ph.grid.symmetry,
                         "symmetry_source": ph.symmetry.source,
                         "peak_direction": tuple(float(x) for x in peak_dir),
                         "luminous_opening": (o.length, o.width, o.height),
                         **application_figures(ph, result.accumulator),
                         "zonal_flux": zonal_flux(emitter_rings(result.accumulator)),
                         **(col.as_dict() if col is not None else {}),
                         **{k: str(v) for k, v in paths.items()}})



def exr_metadata(result: TraceResult, record: ResultRecord) -> dict:
    """The EXR header's JSON metadata: the record's figures plus units and emitters."""
    acc = result.accumulator
    scene = result.scene
    photometric = {f.key: record[f.key] for f in RESULT_FIELDS if f.group == "photometry"}
    photometric["light_output_ratio"] = record["light_output_ratio"]
    return {
        "software": f"lumitrace {__version__}",
        **record.exr_metadata(),
        "units": {"Y": "cd", "raw.Y": "cd", "count": "photons",
                  **({c: "CIE XYZ, Y in cd" for c in ("X", "Z", "raw.X", "raw.Z")}
                     if acc.colour != "none" else {}),
                  "relativeError": "relative standard error of Y per texel (capped at "
                                   f"{MAX_TEXEL_ERROR:g}: no estimate)"},
        "axes": f"stage axes, up {scene.up_axis}",
        "errorDefinition": "estimated relative RMS error of Y over the sphere: "
                           "sqrt(sum(dOmega (Y - Y_true)^2) / sum(dOmega Y_true^2))",
        "emitters": [{"path": t.path, "flux": t.flux, "photons": t.photons}
                     for t in acc.emitters],
        "photometry": photometric,
    }


def output_place(scene, out_dir: str | os.PathLike | None,
                 name: str | None = None) -> tuple[Path | None, Path, str, Path]:
    """Where a scene's results go: (stage file or None, output folder, NAME, folder of the
    result layer). Everything goes to ``out_dir`` when given, else beside the stage. A
    stage with no file of its own (in memory, anonymous) needs ``out_dir``; its NAME is
    ``name`` or the luminaire prim's name."""
    if scene.stage_path:
        stage_path = Path(scene.stage_path).absolute()
        out = Path(out_dir).absolute() if out_dir is not None else stage_path.parent
        return stage_path, out, name or stage_name(stage_path), out
    if out_dir is None:
        raise OutputError("the stage has no file of its own: name an output folder",
                          scene.luminaire_path or None)
    out = Path(out_dir).absolute()
    name = name or scene.luminaire_path.rstrip("/").rsplit("/", 1)[-1] or "luminaire"
    return None, out, name, out


def planned_outputs(scene, out_dir: str | os.PathLike | None, name: str | None = None
                    ) -> tuple[Path | None, str, dict[str, Path]]:
    """(stage file or None, NAME, every output path a run may write, by key): see
    :func:`output_place`."""
    stage_path, out, name, layer_dir = output_place(scene, out_dir, name)
    paths = {"intensity_map": out / f"{name}{INTENSITY_SUFFIX}",
             "latlong_map": out / f"{name}{LATLONG_SUFFIX}",
             **photometric_paths(out, name), **deliverable_paths(out, name),
             "result_layer": layer_dir / f"{name}{RESULT_LAYER_SUFFIX}"}
    return stage_path, name, paths


def claim_planned_outputs(scene, out_dir: str | os.PathLike | None,
                          name: str | None = None, wait: float = DEFAULT_LOCK_WAIT) -> None:
    """Refuse, before any tracing, a run whose outputs would replace a file lumitrace did
    not write for this stage or one the stage reads (see :mod:`.ownership`). A refusal is
    checked again under the publishing lock, after an interrupted commit is finished, as
    the write checks: another run of the stage may be committing, its files and their
    record replaced one after another, and only the lock's holder may do that."""
    stage_path, name, paths = planned_outputs(scene, out_dir, name)
    try:
        claim_outputs(stage_path, paths, scene.input_files())
    except OutputError:
        folders = [paths["result_layer"].parent]
        if not folders[0].is_dir():
            raise
        with locked(folders, name, wait):
            for note in recover(folders, name, [p.name for p in paths.values()]):
                warn(note, OutputWarning)
            claim_outputs(stage_path, paths, scene.input_files())


def write_outputs(result: TraceResult, out_dir: str | os.PathLike | None,
                  wait: float = DEFAULT_LOCK_WAIT, *, name: str | None = None,
                  sublayer: bool = True, pictures: bool = True,
                  extra: dict | None = None, deliverables: bool = False,
                  on_stage: Callable[[Callable[[], None]], None] | None = None,
                  checkpoint: Callable[[], None] = lambda: None,
                  written_layer: Callable[[Path, str], None] | None = None) -> ResultRecord:
    """Write the photometric files, the EXR and the result layer as one transaction (see
    :mod:`lumitrace.publish.transaction`), then sublayer the layer into the stage file
    (unless ``sublayer`` is False, or the stage has no file: see :func:`output_place`);
    return the record. Waits up to ``wait`` s for another run publishing the same NAME.
    ``pictures`` False skips the polar curve and photometric solid (the slow part; the
    record then names none, and the previous run's are removed); ``deliverables`` adds the
    datasheet and the GLDF container (:mod:`.deliverables`); ``extra`` adds entries to
    the EXR header and the result layer's customLayerData (the service's revision).
    ``on_stage(step)`` runs the steps that touch layers open in this process (reloading
    the result layer, sublayering it) and returns what ``step`` returns (the stage's
    :class:`~.sublayer.RootEdit`, None without one): a service passes the runner of its USD
    thread; by default they run here. ``checkpoint`` runs before each picture and the
    deliverables: what it raises abandons the write (the transaction rolled back, the last
    set left whole). Only files lumitrace wrote for this stage are replaced
    (:mod:`.ownership`). ``written_layer(path, sha256)`` is told, under the publishing
    lock and after the stage's steps, which result layer this run wrote and the digest of
    the bytes it wrote there (the command keeps its kept scene valid with it)."""
    scene = result.scene
    stage_path, name, paths = planned_outputs(scene, out_dir, name)
    layer_dir = paths["result_layer"].parent
    drawable = plotting_available()
    if pictures and not drawable:
        warn("the polar curve and the photometric solid are not drawn: matplotlib is not "
             "installed (install lumitrace[plot])", OutputWarning)
    pictures = pictures and drawable
    if deliverables and not drawable:
        warn("the datasheet and the GLDF container are not written: matplotlib is not "
             "installed (install lumitrace[plot])", OutputWarning)
        deliverables = False
    est = result.estimate
    ph = photometry_of(scene, result.accumulator)
    if ph.symmetry.contradicted:
        warn(f"{scene.luminaire_path}.{LUMINAIRE_SYMMETRY}: declared {ph.symmetry.name}, but "
             "the photon counts show a departure from it of more than "
             f"{SYMMETRY_TOLERANCE:.0%} RMS: the files average over a symmetry the "
             "distribution does not have", OutputWarning)
    col = colour_over_angle(result.accumulator)
    if col is None:
        paths.pop("colour_data")
    if not pictures or col is None:
        paths.pop("colour_diagram")
    if not pictures:
        paths.pop("polar_diagram")
        paths.pop("photometric_solid")
    if not deliverables:
        for key in deliverable_paths(layer_dir, name):
            paths.pop(key)
    record = build_record(result, ph, paths, col)
    folders = [layer_dir]
    try:
        layer_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the output folder: {exc.strerror}",
                          str(layer_dir)) from exc
    tx = None
    try:
        with locked(folders, name, wait):
            for note in recover(folders, name, [p.name for p in paths.values()]):
                warn(note, OutputWarning)
            claim = claim_outputs(stage_path, paths, scene.input_files())
            for note in claim.notes:
                warn(note, OutputWarning)
            tx = Transaction(name, layer_dir, removals=list(claim.dropped))
            try:
                staged = {k: tx.staged(v) for k, v in paths.items()}
                write_photometric_files(scene, ph, staged, name, pictures, run_id=tx.run_id,
                                        cct_K=col.total["cct_K"] if col is not None else None,
                                        checkpoint=checkpoint)
                if col is not None:
                    write_colour_files(col, staged, name, pictures, run_id=tx.run_id,
                                       title=scene.info.name, checkpoint=checkpoint)
                if deliverables:
                    checkpoint()
                    write_deliverables(scene, ph, record, staged, paths, run_id=tx.run_id)
                acc = result.accumulator
                channels = {"Y": est.filtered, "raw.Y": est.raw,
                            "count": acc.counts().astype(np.float64),
                            "relativeError": np.minimum(est.texel_error, MAX_TEXEL_ERROR),
                            **colour_maps(acc, est)}
                meta = {**exr_metadata(result, record), **(extra or {}), "runId": tx.run_id,
                        "stagePath": str(stage_path or "")}
                write_intensity_exr(staged["intensity_map"], channels, meta)
                write_latlong_texture(staged["latlong_map"], est.filtered, scene.up_axis)
                owned = ownership_record(stage_path, layer_dir,
                                         {paths[k].name: f for k, f in staged.items()
                                          if k != "result_layer"})
                text = result_layer_text(stage_path, scene.luminaire_path,
                                         record.layer_values(layer_dir),
                                         photometric_light(scene, ph, paths["ies"], layer_dir),
                                         layer_dir,
                                         {**(extra or {}), "runId": tx.run_id, **owned},
                                         (scene.up_axis, scene.meters_per_unit))
                write_layer_file(stage_path, staged["result_layer"], text,
                                 replaces=paths["result_layer"])
                layer_digest = written_layer and file_digest(staged["result_layer"])
                tx.commit(last=paths["result_layer"])
            except Interrupted as exc:
                exc.published = tx.committed
                tx.abort()
                raise
            except BaseException:
                tx.abort()
                raise
            def stage_steps() -> RootEdit | None:
                reload_if_open(paths["result_layer"])
                if sublayer and stage_path is not None:
                    with signals_held():
                        return sublayer_into_root(stage_path, paths["result_layer"])
                return None
            (on_stage or _here)(stage_steps)
            if written_layer is not None:
                written_layer(paths["result_layer"], layer_digest)
    except Interrupted as exc:  # after the commit (the stage's steps, the lock's release)
        exc.published = exc.published or (tx is not None and tx.committed)
        raise
    return record


def _here(step: Callable[[], None]) -> None:
    step()
