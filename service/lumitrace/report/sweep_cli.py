"""The ``lumitrace sweep`` command: its arguments, and the run (:mod:`.sweep`, loaded only
when the command runs: the command line starts without it)."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from ..run.settings import scheduler_address


def add_parser(sub) -> None:
    """The ``lumitrace sweep`` command's arguments."""
    w = sub.add_parser("sweep", help="trace many stages and the variants of their variant "
                                     "sets; one results table and an HTML overview",
                       description="Trace every stage (files, folders, glob patterns) and "
                                   "every combination of its luminaire's variant sets, each "
                                   "into OUT/NAME/[SET-VALUE,...]/ as trace --out writes it; "
                                   "write OUT/sweep.csv, OUT/sweep.json and OUT/index.html. "
                                   "Results already current are not traced again.")
    w.add_argument("stages", nargs="+", help="stage files, folders of stages, glob patterns")
    w.add_argument("--variants", action="append", metavar="SET[=A,B]",
                   help="vary only this variant set (all its variants, or those named); "
                        "repeat for more sets (default: every set, every combination)")
    stop = w.add_mutually_exclusive_group()
    stop.add_argument("--photons", type=float, help="photons per case (default 2e6)")
    stop.add_argument("--target-error", type=float, metavar="E",
                      help="trace each case to this estimated relative error")
    w.add_argument("--resolution", type=int, default=64)
    w.add_argument("--seed", type=int, default=0)
    w.add_argument("--threads", type=int, default=None)
    w.add_argument("--scheduler", type=scheduler_address, metavar="tcp://HOST:PORT",
                   help="run the batches on this Dask scheduler's workers")
    w.add_argument("--out", type=Path, default=Path("sweep"),
                   help="the sweep's folder (default ./sweep)")
    w.add_argument("--pictures", action="store_true",
                   help="draw each case's polar curve and photometric solid (PNG, slow)")
    w.add_argument("--json", action="store_true", help="print the table as one JSON object")
    w.add_argument("--quiet", action="store_true", help="no line per case on stderr")
    w.epilog = ("exit status: 0 every case traced (or current); 1 a case failed (the others "
                "ran, the table names it and why); 2 the sweep could not start (no stage, "
                "another sweep writing into --out); 3 a case missed --target-error")


def command(args) -> int:
    """``lumitrace sweep``: exit 0; 1 when a case failed (the others ran; the table names
    it and why); 3 when a target error was given and a case missed it."""
    from ..run.settings import TraceSettings, default_threads
    from . import sweep_table
    from .sweep import parse_variants, plan, run_sweep, stage_files

    settings = TraceSettings(photons=None if args.photons is None else int(args.photons),
                             target_error=args.target_error, resolution=args.resolution,
                             seed=args.seed, threads=args.threads or default_threads(),
                             scheduler=args.scheduler)
    if settings.scheduler:  # one connection check before anything is traced
        from ..run.cluster import connect

        connect(settings.scheduler).close()
    cases = plan(stage_files(args.stages), parse_variants(args.variants), args.out.resolve())
    say = None if args.quiet or args.json else lambda s: print(s, file=sys.stderr, flush=True)
    rows = run_sweep(cases, settings, args.out.resolve(), args.pictures, say)
    failed = [r for r in rows if r.get("error")]
    if args.json:
        print(json.dumps({"rows": rows, "table": str(args.out / sweep_table.CSV),
                          "overview": str(args.out / sweep_table.HTML),
                          "failed": len(failed)}))
    elif not args.quiet:
        print(f"{len(rows)} cases ({sum(bool(r['traced']) for r in rows)} traced"
              f"{f', {len(failed)} failed' if failed else ''}): "
              f"{args.out / sweep_table.CSV}, {args.out / sweep_table.HTML}")
    for r in failed:
        print(f"lumitrace: error: {r['error']}", file=sys.stderr)
    if failed:
        return 1
    missed = args.target_error is not None and not all(r["converged"] for r in rows)
    return 3 if missed else 0
