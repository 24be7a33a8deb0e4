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
    d.add_argument("--bug-forward", choices=("C0", "C90", "C180", "C270"), default=None,
                   help="the C plane the BUG rating takes as forward (default: the stage's "
                        "lumitrace:bugForward, else C0)")
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
    """Write the datasheet; exit 0 (2 where the published result cannot be reproduced)."""
    from ..publish.check import check_stage
    from ..publish.datasheet import DatasheetInput
    from ..publish.deliverables import write_datasheet
    from ..publish.outputs import build_record, planned_outputs
    from ..photometry.colour import colour_over_angle
    from ..photometry.distribution import photometry_of
    from ..run.session import run
    from ..run.settings import TraceSettings, default_threads
    from ..stage.reader import read_stage

    from ..publish.outputs import plotting_available

    if not plotting_available():
        raise LumitraceError("the datasheet needs matplotlib: install lumitrace[plot]",
                             str(args.stage))
    from ..photometry.bug import facing

    scene = facing(read_stage(args.stage), args.bug_forward)
    name = stage_name(args.stage)
    folder = Path(args.results) if args.results else Path(args.stage).absolute().parent
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
    ph = photometry_of(scene, result.accumulator, settings.seed)
    _, _, paths = planned_outputs(scene, args.results)
    out = Path(args.out) if args.out else Path(args.stage).absolute().parent / \
        f"{name}.datasheet"
    sheet = {"datasheet_html": out / f"{name}.datasheet.html",
             "datasheet_pdf": out / f"{name}.datasheet.pdf"}
    kept = {k: v for k, v in paths.items() if v.is_file() and k != "gldf"} if reproduce \
        else {}
    record = build_record(result, ph, {**kept, **sheet}, colour_over_angle(result.accumulator))
    if reproduce:
        differ = [a for a, k in CHECKED.items() if a in published and
                  published[a] != (record[k] if a != "photons" else int(record[k]))]
        if differ:
            raise LumitraceError("the published result could not be reproduced (its "
                                 f"{', '.join(differ)} differ): trace the stage again",
                                 str(layer))
    solid = kept.get("photometric_solid")
    data = DatasheetInput(record, ph.grid, scene.info,
                          solid.read_bytes() if solid is not None else None,
                          "" if reproduce else "traced for this datasheet, not published")
    write_datasheet(data, sheet["datasheet_html"], sheet["datasheet_pdf"])
    summary = {"datasheet_html": str(sheet["datasheet_html"]),
               "datasheet_pdf": str(sheet["datasheet_pdf"]), "from_published": reproduce,
               "status": status, "input_hash": record["input_hash"]}
    what = "the published result, reproduced" if reproduce else \
        f"a trace of {record['photons']:,} photons: no current published result ({status})"
    print(json.dumps(summary) if args.json else
          f"{sheet['datasheet_html']}\n{sheet['datasheet_pdf']}\n({what})", file=sys.stdout)
    return 0
