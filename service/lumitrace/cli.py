"""The ``lumitrace`` command line: trace a stage, benchmark the tracer."""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import sys
import warnings
from pathlib import Path

from .errors import ClusterLost, Interrupted, LumitraceError, LumitraceWarning
from .publish.preflight import preflight, refuse_hidden_results
from .pyplot import short_setter_docs
from .fit import cli as fit  # its arguments (stdlib only)
from .report import datasheet_command, sweep_cli as sweep  # their arguments (stdlib only)
from .serve.options import add_access_options
from .report.console import pct as _pct, pm as _pm, progress_bar as _progress_bar, summary_text
from .run.settings import DEFAULT_BATCH_SIZE, DEFAULT_THRESHOLD, scheduler_address
from .trace.job import MAX_DEPTH


def _number(text: str) -> float:
    """``text`` as a float (argparse's own error would name our type function)."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None


def _positive_int(text: str) -> int:
    v = _number(text)
    if not (math.isfinite(v) and int(v) > 0):
        raise argparse.ArgumentTypeError(f"must be a finite positive integer, got {text}")
    return int(v)


def _positive_float(text: str) -> float:
    v = _number(text)
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return v


def _non_negative_float(text: str) -> float:
    v = _number(text)
    if not (v >= 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be zero or a positive number, got {text}")
    return v


def _frame(text: str):
    from .trace.prepared import TracingFrame

    try:
        cx, cy, cz, scale = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be four numbers CX,CY,CZ,SCALE, got {text}")
    if not all(math.isfinite(v) for v in (cx, cy, cz, scale)) or scale <= 0:
        raise argparse.ArgumentTypeError(f"must be finite with SCALE > 0, got {text}")
    return TracingFrame((cx, cy, cz), scale)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser; given ``command``, with that command's parser alone
    (building all nine costs every run about 5 ms)."""
    p = argparse.ArgumentParser(
        prog="lumitrace",
        description="Far-field luminous intensity of OpenUSD luminaires by photon tracing.")
    from . import __version__

    p.add_argument("--version", action="version", version=f"lumitrace {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    for name, add in _COMMANDS.items():
        if command in (None, name):
            add(sub)
    return p


def _add_trace(sub) -> None:
    t = sub.add_parser("trace", help="trace a stage and write the intensity map and result layer",
                       description="Trace photons from the stage's UsdLux emitters through its parts, "
                                   "bin the photons that leave by direction into a cube-map intensity "
                                   "map (cd) and write NAME.intensity.exr and NAME.lumitrace.usda.")
    t.add_argument("stage", type=Path, help="the luminaire stage (.usda, .usdc, .usd)")
    stop = t.add_argument_group("when to stop (the first reached; default 2e6 photons)")
    stop.add_argument("--photons", type=_positive_int, help="total photons to trace, e.g. 5e6")
    stop.add_argument("--time", type=_positive_float, metavar="SECONDS", help="trace for this long")
    stop.add_argument("--target-error", type=_positive_float, metavar="E",
                      help="stop at this relative standard error of --target-of, e.g. 0.02")
    stop.add_argument("--target-of", choices=("files", "map"), default="files",
                      help="judge the target on the IES/LDT files (RMS and worst lit value, "
                           "default) or on the intensity map")
    t.add_argument("--resolution", type=_positive_int, default=64,
                   help="cube-map face size in texels (default 64)")
    t.add_argument("--threshold", type=_non_negative_float, default=DEFAULT_THRESHOLD,
                   help="pull-push filter threshold: photons from which a texel trusts its own "
                        f"estimate; 0 writes the raw estimate (default {DEFAULT_THRESHOLD:g})")
    t.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    t.add_argument("--max-depth", type=_positive_int, default=MAX_DEPTH, metavar="N",
                   help=f"scattering events a photon may have before it is cut (default "
                        f"{MAX_DEPTH}); the cut flux is reported")
    t.add_argument("--threads", type=_positive_int, default=None,
                   help="tracing workers (default: all cores); the map does not depend on it")
    t.add_argument("--workers", choices=("auto", "threads", "processes"), default="auto",
                   help="run batches in threads or worker processes; auto uses threads "
                        "(the map does not depend on it)")
    t.add_argument("--scheduler", type=scheduler_address, metavar="tcp://HOST:PORT",
                   help="run the batches on this Dask scheduler's workers (lumitrace[dask]; "
                        "the map does not depend on it); exit 4 if it goes away mid-run")
    t.add_argument("--batch-size", type=_positive_int, default=DEFAULT_BATCH_SIZE, metavar="N",
                   help="photons per batch job (default %(default)s; the map does not "
                        "depend on it)")
    t.add_argument("--out", type=Path, default=None,
                   help="folder for every output, the result layer included (default: "
                        "beside the stage)")
    t.add_argument("--json", action="store_true",
                   help="print one JSON summary object as the last line of stdout")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.add_argument("--frame", type=_frame, default=None, metavar="CX,CY,CZ,SCALE",
                   help="the normalised tracing frame (world m) to trace in, as a service "
                        "reports it, to reproduce its map exactly (default: the stage's own)")
    t.add_argument("--edits", type=Path, default=None, metavar="LAYER",
                   help="compose this edits layer over the stage, as the service does with "
                        "NAME.lumitrace-edits.usda (default: none)")
    t.add_argument("--no-sublayer", action="store_true",
                   help="write the outputs and the result layer, but leave the stage file "
                        "untouched (the result layer is not sublayered into it)")
    t.add_argument("--luminaire", default=None, metavar="PRIM",
                   help="the luminaire prim (default: the stage's defaultPrim)")
    t.add_argument("--time-code", type=float, default=None, metavar="CODE",
                   help="the USD time code to read the stage at (default: its default time)")
    t.add_argument("--quiet", action="store_true",
                   help="print nothing but errors (the exit status says how it went)")
    t.add_argument("--replace-results", action="store_true",
                   help="remove stale lumitrace:result:* opinions from the stage's root layer "
                        "(a stage flattened with its results) before tracing")
    t.add_argument("--no-pictures", action="store_true",
                   help="skip the polar curve and the photometric solid (the slow outputs)")
    t.add_argument("--deliverables", action="store_true",
                   help="also write the datasheet (HTML, PDF) and the GLDF container")


def _add_check(sub) -> None:
    c = sub.add_parser("check", help="are the stage's composed results current? (exit 0 "
                                     "current and converged, 1 stale or missing, 3 not "
                                     "converged, 4 a publishing interrupted, unfinished)",
                       description="Compose the stage and compare its lumitrace:result:* "
                                   "attributes with the scene as it is now: a pipeline gate; "
                                   "a killed run's half-done publishing is finished first.")
    c.add_argument("stage", type=Path)
    c.add_argument("--out", type=Path, default=None,
                   help="the folder a trace wrote the results to (trace --out DIR, with or "
                        "without --no-sublayer): its result layer is judged")
    c.add_argument("--json", action="store_true", help="print one JSON object")


def _add_serve(sub) -> None:
    v = sub.add_parser("serve", help="the live service: watch the stage, accept scene deltas, "
                                     "refine and write results as it goes",
                       description="Trace the stage progressively and keep its results up to "
                                   "date: layer files saved on disk and scene deltas posted "
                                   "over HTTP start a new revision. Accepted deltas live in "
                                   "NAME.lumitrace-edits.usda beside the stage.")
    v.add_argument("stage", type=Path)
    v.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1; another needs --token)")
    v.add_argument("--port", type=int, default=8650, help="port (default 8650; 0 picks one)")
    vstop = v.add_mutually_exclusive_group()
    vstop.add_argument("--photons", type=_positive_int,
                       help="photons per revision (default: trace to --target-error)")
    vstop.add_argument("--target-error", type=_positive_float, metavar="E", help="estimated "
                       "relative RMS error at which a revision is done (default 0.02)")
    v.add_argument("--seed", type=int, default=0)
    v.add_argument("--resolution", type=_positive_int, default=64)
    v.add_argument("--threshold", type=_non_negative_float, default=DEFAULT_THRESHOLD)
    v.add_argument("--threads", type=_positive_int, default=None)
    v.add_argument("--scheduler", type=scheduler_address, metavar="tcp://HOST:PORT",
                   help="trace the rounds on this Dask scheduler's workers (lumitrace[dask])")
    v.add_argument("--no-viewer", action="store_true",
                   help="do not serve the live view page at / (the JSON API only)")
    add_access_options(v, _positive_int, _positive_float)
    v.add_argument("--out", type=Path, default=None,
                   help="output folder (default: beside the stage)")
    v.add_argument("--no-sublayer", action="store_true", help="leave the stage file "
                   "untouched (the result layer is written but not sublayered into it)")
    v.add_argument("--deliverables", action="store_true", help="also write the datasheet "
                   "(HTML, PDF) and the GLDF container, with each revision's pictures")
    v.add_argument("--quiet", action="store_true", help="no line per event on stderr")


def _add_edits(sub) -> None:
    e = sub.add_parser("edits", help="keep or drop the deltas a service accepted",
                       description="merge: fold NAME.lumitrace-edits.usda into the stage's "
                                   "root layer (the edits win) and remove it; discard: remove "
                                   "it. Stop the service first.")
    e.add_argument("action", choices=("merge", "discard"))
    e.add_argument("stage", type=Path)
    e.add_argument("--layer", type=Path, default=None,
                   help="the edits layer (default NAME.lumitrace-edits.usda beside the stage; "
                        "a fit's NAME.lumitrace-fit.usda to keep its best)")


def _add_report(sub) -> None:
    r = sub.add_parser("report", help="convergence report: error against time, raw against filtered",
                       description="Trace the stage and record after every iteration the elapsed "
                                   "time, photons, estimated error and, with a reference (the "
                                   "stage's closed form or --reference EXR), the true relative RMS "
                                   "error, PSNR and SSIM of the raw and filtered maps. Writes "
                                   "report.json, PNG plots and index.html.")
    r.add_argument("stage", type=Path)
    r.add_argument("--reference", type=Path, default=None,
                   help="a long run's NAME.intensity.exr taken as the truth (default: the "
                        "stage's closed form, where it has one)")
    r.add_argument("--out", type=Path, default=None, help="report folder (default NAME.report/ "
                                                          "beside the stage)")
    rstop = r.add_mutually_exclusive_group()
    rstop.add_argument("--photons", type=_positive_int)
    rstop.add_argument("--time", type=_positive_float, default=None, metavar="SECONDS",
                       help="trace for this long (default 30 s)")
    r.add_argument("--resolution", type=_positive_int, default=64)
    r.add_argument("--thresholds", default=f"0,512,2500,{DEFAULT_THRESHOLD:g}",
                   help="comma-separated filter thresholds to compare; 0 is the raw map")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--threads", type=_positive_int, default=None)
    r.add_argument("--no-progress", action="store_true")


def _add_bench(sub) -> None:
    b = sub.add_parser("bench", help="tracer throughput against bare Embree on the same rays",
                       description="Trace the demo stage, replay every traced ray through bare "
                                   "embreex run() and report both rates and their ratio.")
    b.add_argument("--stage", type=Path, default=None, help="stage (default: the demo downlight)")
    b.add_argument("--seconds", type=_positive_float, default=10.0,
                   help="approximate tracing time (default 10)")
    b.add_argument("--threads", type=_positive_int, default=None)
    b.add_argument("--workers", choices=("processes", "threads"), default="processes",
                   help="run batches in worker processes (each alone in its process, as "
                        "the bare-Embree reference runs) or threads")
    b.add_argument("--json", action="store_true", help="print one JSON object")


def _add_rays(sub) -> None:
    y = sub.add_parser("rays", help="write the luminaire's exit rays as an IES TM-25 ray file",
                       description="Trace photons through the luminaire and write every "
                                   "escaping one as a ray (where it leaves the luminaire's box, "
                                   "mm, its direction and flux, in the luminaire's frame): the "
                                   "luminaire as a near-field source for optics tools, or for "
                                   "a light's lumitrace:rayFile.")
    y.add_argument("stage", type=Path)
    y.add_argument("--photons", type=_positive_int, default=1_000_000,
                   help="photons to trace (default 1e6): the rays are those that escape")
    y.add_argument("--seed", type=int, default=0)
    y.add_argument("--out", type=Path, default=None,
                   help="the ray file (default NAME.TM25RAY beside the stage)")
    y.add_argument("--max-rays", type=_positive_int, default=None,
                   help="refuse more photons than this (default 20e6: 560 MB)")
    y.add_argument("--luminaire", default=None, help="the luminaire prim (default: defaultPrim)")
    y.add_argument("--luminance-images", type=Path, default=None, metavar="DIR",
                   help="also write luminance images (EXR, PNG, JSON) of the standard views")


#: Each command's parser, added by name: a command line parses with its own alone.
_COMMANDS = {"trace": _add_trace, "check": _add_check, "serve": _add_serve,
             "edits": _add_edits, "report": _add_report, "bench": _add_bench,
             "rays": _add_rays, "sweep": sweep.add_parser,
             "datasheet": datasheet_command.add_parser, "fit": fit.add_parser}


_QUIET = False


def cmd_trace(args) -> int:
    global _QUIET
    _QUIET = bool(args.quiet)
    from .publish.check import NOT_CONVERGED as NOT_CONVERGED_EXIT
    from .publish.outputs import claim_planned_outputs, write_outputs
    from .run.session import run
    from .run.settings import TraceSettings, default_threads
    from .stage.scene_cache import read_stage
    from .trace.compiled import note

    settings = TraceSettings(photons=args.photons, seconds=args.time,
                             target_error=args.target_error, resolution=args.resolution,
                             threshold=args.threshold, seed=args.seed, max_depth=args.max_depth,
                             threads=args.threads or default_threads(), workers=args.workers,
                             scheduler=args.scheduler, batch_size=args.batch_size,
                             target_of=args.target_of)
    check_interrupted(defer=True)
    preflight(args.stage, args.out)
    if not args.no_pictures:  # VTK loads on another core while the photons are traced
        from .photometry.solid_render import start_renderer

        start_renderer(fork=True)
    if args.edits is not None:
        from .delta.edits import open_with_edits
        from .stage.reader import scene_from_stage

        if not args.edits.is_file():
            raise LumitraceError("edits layer not found", str(args.edits))
        scene = scene_from_stage(open_with_edits(args.stage, args.edits), args.luminaire,
                                 time=args.time_code)
    else:
        scene = read_stage(args.stage, args.luminaire, time_code=args.time_code)
    if not args.no_sublayer:
        if args.replace_results:
            from .publish.check import strip_result_opinions

            for prim in strip_result_opinions(args.stage):
                print(f"warning: {args.stage}: removed the stale lumitrace:result:* opinions "
                      f"on {prim} from its root layer", file=sys.stderr)
        refuse_hidden_results(args.stage)
    claim_planned_outputs(scene, args.out)
    if args.frame is not None:
        args.frame.check_fits(scene)
    for w in () if args.quiet else scene.warnings:
        print(f"warning: {w}", file=sys.stderr)
    check_interrupted()
    if note() and not args.quiet:
        print(f"note: {note()}", file=sys.stderr)

    bar, update = _progress_bar(settings.budget(), args.time,
                                not (args.no_progress or args.json or args.quiet))
    lost = None
    try:
        from . import STARTED

        result = run(scene, settings, progress=update, frame=args.frame, clock_start=STARTED,
                     progress_maps=settings.target_of == "map")
    except ClusterLost as exc:  # the batches that finished are written, then it is said
        result, lost = exc.result, exc
    finally:
        if bar is not None:
            bar.close()
    check_interrupted()
    vouch = None
    if args.edits is None and not args.no_sublayer:  # the next run keeps its kept scene
        from .stage.scene_cache import vouch as keep_valid

        def vouch(layer, digest):
            keep_valid(args.stage, args.luminaire, args.time_code, layer, digest)
    record = write_outputs(result, args.out, sublayer=not args.no_sublayer,
                           pictures=not args.no_pictures, deliverables=args.deliverables,
                           written_layer=vouch)
    if lost is not None:
        raise lost.written(record["photons"])
    if _RECEIVED:  # a signal a library swallowed while the outputs were written
        stop = Interrupted(_RECEIVED[0])
        stop.published = True
        raise stop
    summary = record.summary()
    target = args.target_error
    bound = record["judged_error"]
    missed = target is not None and not record["converged"]
    summary["target_reached"] = None if target is None else not missed
    summary["warnings"] = list(scene.warnings) + _SHOWN
    text = json.dumps(summary) if args.json else "" if args.quiet else \
        summary_text(record, args.stage)
    if missed and not (args.json or args.quiet):
        judged = "files'" if record["target_of"] == "files" else "map's"
        text += (f"\nnot converged: the {judged} error {_pct(bound)} > {target:.2%} "
                 f"(exit status {NOT_CONVERGED_EXIT})")
    try:
        if text:
            print(text)
        sys.stdout.flush()
    except OSError as exc:
        sys.stdout = open(os.devnull, "w")  # nothing more to say there, even at exit
        raise LumitraceError(f"the outputs were written, but the summary could not be "
                             f"printed: {exc.strerror or exc}", "standard output") from None
    return NOT_CONVERGED_EXIT if missed else 0


def cmd_rays(args) -> int:
    from .filenames import stage_name
    from .publish.rays import MAX_RAYS, check_ray_count, claim_ray_file, write_ray_file
    from .stage.reader import read_stage
    from .trace.exit_rays import exit_rays

    scene = read_stage(args.stage, args.luminaire)
    out = args.out or args.stage.with_name(f"{stage_name(args.stage)}.TM25RAY")
    check_ray_count(out, args.photons, args.max_rays or MAX_RAYS)
    claim_ray_file(out, scene)  # before the trace: a refusal costs no photons
    rays = exit_rays(scene, args.photons, args.seed)
    write_ray_file(out, rays, scene)
    if args.luminance_images is not None:
        from .publish.luminance_images import images_from_rays
        images = images_from_rays(rays, scene, args.luminance_images, stage_name(args.stage))
        print(f"{args.luminance_images}: {len(images)} luminance images")
    print(f"{out}: {len(rays):,} rays, {rays.flux.astype(float).sum():.6g} lm "
          f"(of {args.photons:,} photons)")
    return 0


def cmd_check(args) -> int:
    from .publish.check import check_stage

    verdict = check_stage(args.stage, args.out)
    for note in verdict.values.get("recovered", ()):
        print(f"warning: {note}", file=sys.stderr)
    print(json.dumps(verdict.as_dict()) if args.json else f"{args.stage}: {verdict.status}: "
          f"{verdict.message}")
    return verdict.exit_status


def cmd_serve(args) -> int:
    from .run.settings import DEFAULT_TARGET_ERROR, TraceSettings, default_threads
    from .serve.server import serve

    target = args.target_error if args.target_error is not None else \
        None if args.photons else DEFAULT_TARGET_ERROR
    settings = TraceSettings(photons=args.photons, target_error=target,
                             resolution=args.resolution, threshold=args.threshold,
                             seed=args.seed, threads=args.threads or default_threads(),
                             workers="threads", scheduler=args.scheduler)
    preflight(args.stage, args.out, stage_folder_written=True)
    if not 0 <= args.port <= 65535:
        raise LumitraceError(f"--port must be 0..65535, got {args.port}")
    from .serve.guard import read_token

    token = read_token(args.token, args.token_file)
    from .photometry.solid_render import start_renderer

    # the solids drawn off this process's interpreter, which edits need, in a window
    # warmed up while the service starts (forked now: no other thread runs yet)
    start_renderer(warm_up=True, fork=True)
    return serve(args.stage, settings, args.host, args.port, token, args.out, quiet=args.quiet,
                 viewer=not args.no_viewer, sublayer=not args.no_sublayer,
                 deliverables=args.deliverables, allow_hosts=args.allow_host,
                 limits=(args.max_photons, args.min_target_error))


def cmd_edits(args) -> int:
    from .delta.edits import discard_edits, merge_edits
    from .filenames import edits_layer_path

    path = args.layer or edits_layer_path(args.stage)
    if args.action == "merge":
        merge_edits(args.stage, args.layer)
        print(f"merged {path.name} into {args.stage} and removed it")
    else:
        print(f"removed {path.name}" if discard_edits(args.stage, args.layer) else
              f"no edits layer ({path.name}) to discard")
    return 0


def cmd_report(args) -> int:
    import os

    from .filenames import stage_name
    from .report.convergence_report import ReportSettings, run_report

    try:
        thresholds = tuple(sorted({float(x) for x in args.thresholds.split(",") if x.strip()}))
    except ValueError:
        raise LumitraceError(f"--thresholds must be numbers separated by commas, got "
                             f"{args.thresholds!r}")
    if not thresholds or min(thresholds) < 0:
        raise LumitraceError("--thresholds must be zero or positive")
    seconds = args.time if args.time is not None else (None if args.photons else 30.0)
    settings = ReportSettings(photons=args.photons, seconds=seconds, resolution=args.resolution,
                              thresholds=thresholds, seed=args.seed,
                              threads=args.threads or os.cpu_count() or 1)
    out = args.out or args.stage.parent / f"{stage_name(args.stage)}.report"
    from .stage.reader import read_stage

    for w in read_stage(args.stage).warnings:
        print(f"warning: {w}", file=sys.stderr)
    bar, update = _progress_bar(args.photons, seconds, not args.no_progress)
    try:
        written = run_report(args.stage, out, settings, args.reference, progress=update)
    finally:
        if bar is not None:
            bar.close()
    data = written["data"]
    print(f"report     {written['html']}")
    print(f"photons    {data['photons']:,} in {data['iterations']} iterations, {data['seconds']:.1f} s")
    print(f"reference  {data['reference'] or 'none (estimated errors only)'}")
    f = data["figures"]
    print(f"flux       {_pm(f['luminous_flux'], f['luminous_flux_error'], 'lm', 1)}, light "
          f"output ratio {_pm(f['light_output_ratio'], f['light_output_ratio_error'], '', 4)}")
    print(f"peak       {_pm(f['peak_intensity'], f['peak_intensity_error'], 'cd', 1)}; beam "
          f"{_pm(f['beam_angle_c0_c180'], f['beam_angle_c0_c180_error'], 'deg', 1)} "
          f"(C0-C180), CIE flux code {f['cie_flux_code']}")
    for key, c in data["time_to_error"].items():
        label = "raw" if key == "0" else f"threshold {key}"
        cells = ", ".join(f"{float(lv):.0%} at {t:.3g} s" if t else f"{float(lv):.0%} not reached"
                          for lv, t in c.items())
        sp = {lv: v for lv, v in (data["speedup_filtered_over_raw"].get(key) or {}).items() if v}
        extra = "" if not sp else "  (" + ", ".join(
            f"{v:.1f}x faster to {float(lv):.0%}" for lv, v in sp.items()) + ")"
        print(f"  {label:14s} {cells}{extra}")
    return 0


def cmd_bench(args) -> int:
    from .run.bench import run_benchmark, summary_text

    report = run_benchmark(stage=args.stage, seconds=args.seconds, threads=args.threads,
                           workers=args.workers)
    print(json.dumps(report) if args.json else summary_text(report))
    return 0


_python_showwarning = warnings.showwarning
#: lumitrace warnings shown in this run (the --json summary lists them too)
_SHOWN: list[str] = []


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """lumitrace's warnings as one line each on stderr; others as Python shows them."""
    if issubclass(category, LumitraceWarning):
        _SHOWN.append(str(message))
        if not _QUIET:
            print(f"warning: {message}", file=sys.stderr)
    else:
        _python_showwarning(message, category, filename, lineno, file, line)


HANDLED_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


#: Signals received in this process: USD's module loader can swallow the exception a
#: handler raises during an import, so the command also checks this between its phases.
_RECEIVED: list[int] = []
#: While True (imports and reading the stage, where USD loads its modules), a signal is
#: only recorded; :func:`check_interrupted` acts on it once that phase is over.
_DEFERRING = [True]


def _raise_interrupted(signum, frame) -> None:
    _RECEIVED.append(signum)
    if not _DEFERRING[0]:
        raise Interrupted(signum)


def _unraisable(hook):
    """``sys.unraisablehook`` that keeps quiet about an :class:`Interrupted` raised where
    Python cannot pass it on (a finalizer or weakref callback, say a plotting library's
    during the write): the signal is recorded, and the command acts on it between phases."""
    def quiet(unraisable) -> None:
        if not isinstance(unraisable.exc_value, Interrupted):
            hook(unraisable)
    return quiet


def check_interrupted(defer: bool = False) -> None:
    """Raise :class:`Interrupted` for a signal received earlier; from now on (unless
    ``defer``) signals raise at once."""
    _DEFERRING[0] = defer
    if _RECEIVED:
        raise Interrupted(_RECEIVED[0])


def _interrupted_message(exc: Interrupted) -> str:
    name = signal.Signals(exc.signum).name
    if exc.published:
        return (f"lumitrace: {name}: interrupted after this run's outputs were published "
                "(they are complete)")
    return f"lumitrace: {name}: interrupted; nothing was written, earlier outputs are unchanged"


def _dispatch(args) -> int:
    if args.command == "trace":
        return cmd_trace(args)
    check_interrupted()  # the others have no USD-loading phase of their own
    return {"report": cmd_report, "bench": cmd_bench, "serve": cmd_serve, "edits": cmd_edits,
            "check": cmd_check, "rays": cmd_rays, "sweep": sweep.command,
            "datasheet": datasheet_command.command, "fit": fit.command}[args.command](args)


def _failure(exc: BaseException) -> tuple[int, str]:
    """The exit status and the one line for a run that failed with ``exc``; None's
    status for an exception that is no user-facing failure."""
    if isinstance(exc, LumitraceError):
        return getattr(exc, "exit_status", 2), f"lumitrace: error: {exc}"
    if isinstance(exc, Interrupted):
        return 128 + exc.signum, _interrupted_message(exc)
    if isinstance(exc, KeyboardInterrupt):
        return 130, "lumitrace: interrupted; nothing was written, earlier outputs are unchanged"
    where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
    return 2, f"lumitrace: error: {where}{getattr(exc, 'strerror', None) or exc}"


def _interruption(exc: BaseException) -> Interrupted | None:
    """The :class:`Interrupted` that caused ``exc``, where a library wrapped it (a signal
    that lands in an import can come out as its RuntimeError); else None."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, Interrupted):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def main(argv: list[str] | None = None, early_signals: list[int] | None = None) -> int:
    """The command line; ``early_signals`` are signals the entry point caught before
    lumitrace was imported (the run then stops before it starts). A command given
    ``--json`` prints one JSON object on stdout whatever happens, a failure included."""
    for name in ("stdout", "stderr"):  # a closed stream (``>&-``) is one nobody reads
        if getattr(sys, name) is None:
            setattr(sys, name, open(os.devnull, "w"))
    previous = {s: signal.signal(s, _raise_interrupted) for s in HANDLED_SIGNALS}
    hook, sys.unraisablehook = sys.unraisablehook, _unraisable(sys.unraisablehook)
    args = None
    try:
        _RECEIVED.extend(early_signals or ())
        check_interrupted(defer=True)
        given = sys.argv[1:] if argv is None else argv
        args = build_parser(given[0] if given and given[0] in _COMMANDS else None
                            ).parse_args(argv)
        warnings.showwarning = _show_warning
        short_setter_docs()  # this process draws pictures and never shows a docstring
        return _dispatch(args)
    except (Exception, Interrupted, KeyboardInterrupt) as exc:  # the rest raised again
        failure = exc if isinstance(exc, (LumitraceError, Interrupted, KeyboardInterrupt,
                                          OSError)) else _interruption(exc)
        if failure is None:
            raise
        code, line = _failure(failure)
        print(line, file=sys.stderr)
        if getattr(args, "json", False):
            with contextlib.suppress(OSError, ValueError):
                message = line.removeprefix("lumitrace: ").removeprefix("error: ")
                print(json.dumps({"error": message, "exit_status": code,
                                  "command": args.command}), flush=True)
        return code
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
        sys.unraisablehook = hook


if __name__ == "__main__":  # pragma: no cover
    from lumitrace.quick_exit import finish

    sys.exit(finish(main()))
