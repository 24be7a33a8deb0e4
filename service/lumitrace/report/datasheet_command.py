"""``lumitrace datasheet STAGE``: the datasheet (HTML, PDF) of a stage's published result.

The photon path of photon i is a pure function of (scene, seed, i), so the published result
is reproduced exactly by tracing its photons again with its recorded seed, resolution and
threshold: the datasheet is made from that record, the one the files were made from, and
the command checks it against the result layer (input hash, flux, peak) before writing. A
stage with no current result (none, or stale) is traced with ``--photons`` and ``--seed``
(nothing of the stage's outputs is written then; the page says it was traced for the
datasheet). The pages go to ``--out`` (default ``NAME.datasheet/`` beside the stage); ``trace
--deliverables`` writes them, with the GLDF container, among the run's own outputs.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from ..errors import LumitraceError
from ..filenames import RESULT_LAYER_SUFFIX, stage_name

#: Result-layer attributes (after ``lumitrace:result:``) compared with the reproduction.
CHECKED = {"inputHash": "input_hash", "luminousFlux": "escaped_lm",
           "peakIntensity": "peak_intensity", "photons": "photons"}


def add_parser(sub) -> None:
    """The ``lumitrace datasheet`` command's arguments."""
    d = sub.add_parser("datasheet", help="the datasheet (HTML, PDF) of the stage's result",
                       description="Write NAME.datasheet.html and NAME.datasheet.pdf from the "
                                   "stage's published result (reproduced exactly from its "
                                   "recorded photons and seed), or, where it has none that "
                                   "is current, from a trace of --photons photons.")
    d.add_argument("stage", type=Path)
    d.add_argument("--results", type=Path, default=None, metavar="DIR",
                   help="the folder trace --out wrote the result to (default: beside the "
                        "stage)")
    d.add_argument("--out", type=Path, default=None,
                   help="folder of the datasheet (default NAME.datasheet/ beside the stage)")
    d.add_argument("--photons", type=float, default=2e6,
                   help="photons of a trace when there is no current result (default 2e6)")
    d.add_argument("--seed", type=int, default=0, help="its seed (default 0)")
    d.add_argument("--threads", type=int, default=None)
    d.add_argument("--json", action="store_true", help="print one JSON object")


def published_values(layer: Path, prim_path: str) -> dict:
    """The ``lumitrace:result:*`` values a result layer holds on the luminaire prim."""
    from pxr import Sdf

    from ..schema import RESULT_PREFIX

    data = Sdf.Layer.FindOrOpen(str(layer)) if layer.is_file() else None
    spec = data.GetPrimAtPath(prim_path) if data is not None else None
    if not spec:
        return {}
    return {name[len(RESULT_PREFIX):]: spec.attributes[name].default
            for name in spec.attributes.keys() if name.startswith(RESULT_PREFIX)}


def command(args) -> int:
    """Write the datasheet; exit 0 (2 where the published result cannot be reproduced, or
    where a file in the datasheet's place is not one lumitrace wrote for this stage)."""
    from ..publish.check import check_stage
    from ..publish.datasheet import DatasheetInput
    from ..publish.datasheet_files import claim_datasheet, publish_datasheet
    from ..publish.outputs import build_record, planned_outputs
    from ..publish.ownership import vouched_bytes
    from ..photometry.colour import colour_over_angle
    from ..photometry.distribution import photometry_of
    from ..run.session import run
    from ..run.settings import TraceSettings, default_threads
    from ..stage.reader import read_stage

    from ..publish.outputs import plotting_available

    if not plotting_available():
        raise LumitraceError("the datasheet needs matplotlib: install lumitrace[plot]",
                             str(args.stage))
    scene = read_stage(args.stage)
    name = stage_name(args.stage)
    stage_path = Path(args.stage).absolute()
    out = Path(args.out) if args.out else stage_path.parent / f"{name}.datasheet"
    claim_datasheet(stage_path, out, name, scene.input_files())  # before any photon
    folder = Path(args.results) if args.results else stage_path.parent
    layer = folder / f"{name}{RESULT_LAYER_SUFFIX}"
    status = check_stage(args.stage, args.results).status
    published = published_values(layer, scene.luminaire_path) \
        if status in ("current", "not converged") else {}
    reproduce = bool(published.get("photons"))
    settings = TraceSettings(
        photons=int(published["photons"]) if reproduce else int(args.photons),
        seed=int(published.get("seed", args.seed)) if reproduce else args.seed,
        resolution=int(published.get("resolution", 64)) if reproduce else 64,
        threads=args.threads or default_threads(),
        **({"threshold": float(published["threshold"])}
           if reproduce and "threshold" in published else {}))
    result = run(scene, settings)
    ph = photometry_of(scene, result.accumulator)
    _, _, paths = planned_outputs(scene, args.results)
    # the published files the result layer vouches for (their SHA-256 recorded when they
    # were written): no other file is named, read or embedded
    kept = {k: v for k, v in paths.items() if k not in ("gldf", "result_layer")
            and vouched_bytes(layer, v) is not None} if reproduce else {}
    sheet = {"datasheet_html": out.absolute() / f"{name}.datasheet.html",
             "datasheet_pdf": out.absolute() / f"{name}.datasheet.pdf"}
    record = build_record(result, ph, {**kept, **sheet}, colour_over_angle(result.accumulator))
    if reproduce:
        differ = [a for a, k in CHECKED.items() if a in published and
                  published[a] != (record[k] if a != "photons" else int(record[k]))]
        if differ:
            raise LumitraceError("the published result could not be reproduced (its "
                                 f"{', '.join(differ)} differ): trace the stage again",
                                 str(layer))
    solid = None
    if reproduce and "photometric_solid" in published_files(layer, paths):
        solid = vouched_bytes(layer, paths["photometric_solid"]) or \
            _solid_png(scene, ph, record)  # changed, replaced or gone: drawn again
    data = DatasheetInput(record, ph.grid, scene.info, solid,
                          "" if reproduce else "traced for this datasheet, not published")
    publish_datasheet(data, stage_path, out, name, scene.input_files(),
                      {"inputHash": record["input_hash"], "fromPublished": reproduce,
                       "status": status})
    summary = {"datasheet_html": str(sheet["datasheet_html"]),
               "datasheet_pdf": str(sheet["datasheet_pdf"]), "from_published": reproduce,
               "status": status, "input_hash": record["input_hash"],
               "solid_redrawn": solid is not None and "photometric_solid" not in kept}
    what = "the published result, reproduced" if reproduce else \
        f"a trace of {record['photons']:,} photons: no current published result ({status})"
    print(json.dumps(summary) if args.json else
          f"{sheet['datasheet_html']}\n{sheet['datasheet_pdf']}\n({what})", file=sys.stdout)
    return 0


def published_files(layer: Path, paths: dict) -> set[str]:
    """The output keys of ``paths`` whose files the result layer records."""
    from ..publish.ownership import recorded_files

    names = recorded_files(layer)
    return {k for k, v in paths.items() if Path(v).name in names}


def _solid_png(scene, ph, record) -> bytes:
    """The photometric solid drawn again (PNG bytes), as the trace drew it."""
    import tempfile

    from ..photometry.diagrams import photometric_solid
    from ..publish.datasheet_content import luminaire_name
    from ..publish.transaction import signals_held

    fig = ph.figures
    title = f"{luminaire_name(record, scene.info)}: {fig.luminous_flux:.0f} lm, " \
            f"LOR {fig.light_output_ratio:.2f}"
    with tempfile.TemporaryDirectory(prefix="lumitrace-solid-") as tmp:
        path = Path(tmp) / "solid.png"
        with signals_held():  # VTK does not survive an exception raised inside it
            photometric_solid(path, ph.grid, scene, title)
        return path.read_bytes()
