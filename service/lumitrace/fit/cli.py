"""The ``lumitrace fit`` command: its arguments, and the run (the fit's modules load only
when the command runs: the command line starts without them)."""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from ..run.settings import scheduler_address

#: Photons per candidate at first, and the default most as a multiple of it.
DEFAULT_PHOTONS = 1 << 16
MAX_PHOTONS_FACTOR = 16
DEFAULT_EVALUATIONS = 120
#: The files' error the best is traced to at the end, to confirm its merit.
DEFAULT_FINAL_ERROR = 0.02


def _count(text: str) -> int:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number, got {text}") from None
    if not (math.isfinite(v) and v >= 1 and v == int(v)):
        raise argparse.ArgumentTypeError(f"must be a whole number of at least 1, got {text}")
    return int(v)


def _seconds(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return v


def _fraction(text: str) -> float:
    v = _seconds(text)
    if v >= 1:
        raise argparse.ArgumentTypeError(f"must be between 0 and 1, got {text}")
    return v


def add_parser(sub) -> None:
    """The ``lumitrace fit`` command's arguments."""
    f = sub.add_parser(
        "fit", help="fit parameters of the stage to a target distribution or to figures",
        description="Search the values of the --vary parameters for which the luminaire's "
                    "distribution best matches a target file (shape only, or --absolute) "
                    "and its figures their goals and bounds: CMA-ES over candidates traced "
                    "with common random numbers, the photons per candidate growing as the "
                    "search closes in. The stage is never changed: the best is written as "
                    "an edits layer NAME.lumitrace-fit.usda with its traced files, fit.json "
                    "and fit.html in --out. An interrupted fit resumes from its journal "
                    "when run again.")
    f.add_argument("stage", type=Path, help="the luminaire stage (.usda, .usdc, .usd)")
    f.add_argument("--target", type=Path, default=None, metavar="FILE",
                   help="the target distribution: an IES (LM-63) or EULUMDAT (.ldt) file")
    f.add_argument("--objective", nargs="+", action="extend", default=None, metavar="TERM",
                   help='figure goals "NAME = VALUE" (e.g. "beam_angle_c0_c180 = 30")')
    f.add_argument("--constrain", nargs="+", action="extend", default=None, metavar="EXPR",
                   help='bounds "NAME <= VALUE" or "NAME >= VALUE" (e.g. '
                        '"light_output_ratio >= 0.8")')
    f.add_argument("--vary", nargs="+", action="extend", required=True, metavar="PARAM",
                   help="PATH.PROPERTY[=LO:HI | =+-D], PATH.PROPERTY[i][k][=...] (a "
                        "component; [*] every element, [A:B] elements A to B - 1), "
                        "PATH{VARIANTSET}[=A,B]; the range "
                        "defaults to the schema's where it has one")
    f.add_argument("--absolute", action="store_true",
                   help="compare candela with the target's, not the shape (cd/klm)")
    f.add_argument("--symmetry", default=None,
                   choices=("none", "rotational", "quadrant", "C0-C180", "C90-C270"),
                   help="judge the match in this symmetry (default: the target's)")
    f.add_argument("--photons", type=_count, default=DEFAULT_PHOTONS,
                   help=f"photons per candidate at first (default {DEFAULT_PHOTONS:,}); "
                        "doubled as the search closes in")
    f.add_argument("--max-photons", type=_count, default=None, metavar="N",
                   help=f"most photons per candidate (default {MAX_PHOTONS_FACTOR} x "
                        "--photons)")
    stop = f.add_mutually_exclusive_group()
    stop.add_argument("--evaluations", type=_count, default=None, metavar="N",
                      help=f"candidates to trace (default {DEFAULT_EVALUATIONS}; whole "
                           "generations)")
    stop.add_argument("--time", type=_seconds, default=None, metavar="SECONDS",
                      help="search for this long")
    f.add_argument("--final-error", type=_fraction, default=DEFAULT_FINAL_ERROR,
                   metavar="E", help="trace the best again to this files' error to confirm "
                                     f"its merit (default {DEFAULT_FINAL_ERROR})")
    f.add_argument("--seed", type=int, default=0,
                   help="the photons' seed, one for all candidates (default 0); the "
                        "confirming trace uses the next one")
    f.add_argument("--popsize", type=_count, default=None,
                   help="candidates per generation (default: CMA-ES's for the dimension)")
    f.add_argument("--workers", choices=("threads", "processes"), default="threads",
                   help="trace candidates side by side on threads (default) or worker "
                        "processes")
    f.add_argument("--threads", type=_count, default=None,
                   help="candidates traced at once (default: all cores)")
    f.add_argument("--scheduler", type=scheduler_address, metavar="tcp://HOST:PORT",
                   help="trace the candidates on this Dask scheduler's workers")
    f.add_argument("--no-selective", action="store_true",
                   help="trace every candidate afresh (default: retrace only the photons a "
                        "candidate's change can touch where that is cheaper; the merits are "
                        "the same)")
    f.add_argument("--fresh", action="store_true",
                   help="ignore the journal of an interrupted fit and start again")
    f.add_argument("--out", type=Path, default=None,
                   help="the fit's folder (default NAME.fit beside the stage)")
    f.add_argument("--luminaire", default=None, metavar="PRIM",
                   help="the luminaire prim (default: the stage's defaultPrim)")
    f.add_argument("--no-pictures", action="store_true",
                   help="no report pictures, polar curve, solid or datasheet")
    f.add_argument("--json", action="store_true",
                   help="print one JSON object as the last line of stdout")
    f.add_argument("--no-progress", action="store_true", help="no progress bar")
    f.add_argument("--quiet", action="store_true", help="print nothing but errors")


def command(args) -> int:
    """``lumitrace fit``: exit 0, 2 on bad input (before anything is traced)."""
    from .run import FitOptions, run_fit

    opts = FitOptions(stage=args.stage, target=args.target, objectives=args.objective,
                      constraints=args.constrain, vary=args.vary, absolute=args.absolute,
                      symmetry=args.symmetry, photons=args.photons,
                      max_photons=args.max_photons, evaluations=args.evaluations,
                      seconds=args.time, final_error=args.final_error, seed=args.seed,
                      popsize=args.popsize, workers=args.workers, threads=args.threads,
                      scheduler=args.scheduler, selective=not args.no_selective,
                      fresh=args.fresh, out=args.out, luminaire=args.luminaire,
                      pictures=not args.no_pictures)
    say = None if args.quiet or args.json else (
        lambda s: print(s, file=sys.stderr, flush=True))
    show = not (args.no_progress or args.json or args.quiet)
    from ..errors import Interrupted

    try:
        summary = run_fit(opts, say=say, progress=show)
    except Interrupted as exc:
        journal = getattr(exc, "fit_journal", None)
        held = _generations(journal) if journal is not None else 0
        if held and not args.quiet:
            print(f"lumitrace fit: {journal} holds the {held} generation(s) traced so far: "
                  "run the same command again to resume", file=sys.stderr, flush=True)
        raise
    if args.json:
        print(json.dumps(summary))
    elif not args.quiet:
        print(summary_text(summary))
    return 0


def _generations(journal: Path) -> int:
    """Generations a journal holds (its whole lines after the first)."""
    try:
        text = Path(journal).read_text(encoding="utf-8")
    except OSError:
        return 0
    return sum(1 for line in text.split("\n")[1:] if '"kind":"generation"' in line)


def summary_text(s: dict) -> str:
    """The human summary of a fit."""
    width = max(len(k) for k in s["best"]) if s["best"] else 0
    lines = [f"fit of {s['stage']}: {s['evaluations']} evaluations in {s['seconds']:.1f} s "
             f"({s['stopped']})"]
    for name, value in s["best"].items():
        p = s["parameters"][name]
        edge = f"  (at its {p['at_edge']} edge)" if p.get("at_edge") else ""
        v = value if isinstance(value, str) else f"{value + 0.0:.6g}"
        start = p["start"] if isinstance(p["start"], str) else f"{p['start'] + 0.0:.6g}"
        lines.append(f"  {name:<{width}}  {v}  (from {start}){edge}")
    floor = f"; noise floor {s['noise_floor']:.2g}" if s.get("match") is not None else ""
    lines.append(f"  merit        {s['merit']:.4g} +- {s['merit_error']:.2g} (confirmed at "
                 f"{s['final_photons']:,} photons, seed {s['final_seed']}{floor})")
    lines.append(f"  search merit {s['search_merit']:.4g} +- {s['search_merit_error']:.2g} at "
                 f"{s['search_photons']:,} photons")
    for t in s.get("terms", []):
        v = "undefined" if t["value"] is None else f"{t['value']:.4g}"
        e = "" if t["error"] is None else f" +- {t['error']:.2g}"
        met = "" if t["met"] is None else ("  met" if t["met"] else "  NOT met")
        lines.append(f"  {t['term']:<30} {v}{e}{met}")
    lines.append(f"  edits layer  {s['edits']}")
    lines.append(f"  report       {s['report']}  {s['report_json']}")
    return "\n".join(lines)
