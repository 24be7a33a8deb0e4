"""What the application figures add to a run: the UGR table, the luminance table, the BUG
rating, the cone diagram and the isolux values of the demo stage, timed one by one and all
together (as the record builds them), median wall seconds of the repeats, after one warm-up.

    python tools/application_cost.py [--photons 2000000] [--repeats 5] [--json]
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "service"))

from lumitrace.photometry.bug import bug_rating  # noqa: E402
from lumitrace.photometry.distribution import photometry_of  # noqa: E402
from lumitrace.photometry.illuminance import cone_diagram, isolux  # noqa: E402
from lumitrace.photometry.luminance import luminance_table  # noqa: E402
from lumitrace.photometry.tables import application_figures  # noqa: E402
from lumitrace.photometry.ugr import ugr_table  # noqa: E402
from lumitrace.run.session import TraceSettings, run  # noqa: E402
from lumitrace.stage.reader import read_stage  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=float, default=2e6)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    scene = read_stage(ROOT / "stages" / "downlight.usda")
    result = run(scene, TraceSettings(photons=int(args.photons), resolution=32, threads=2))
    acc = result.accumulator
    ph = photometry_of(scene, acc)
    parts = {"ugr_table": lambda: ugr_table(ph.grid, ph.opening),
             "luminance_table": lambda: luminance_table(ph.grid, ph.opening),
             "bug_rating": lambda: bug_rating(acc),
             "cone_diagram": lambda: cone_diagram(ph.grid, ph.figures),
             "isolux": lambda: isolux(ph.grid),
             "all (application_figures)": lambda: application_figures(ph, acc)}
    seconds = {}
    for name, fn in parts.items():
        fn()  # warm-up: first calls build caches
        times = []
        for _ in range(max(args.repeats, 1)):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        seconds[name] = statistics.median(times)
    table = ugr_table(ph.grid, ph.opening)
    value, error = table.catalogue()
    report = {"photons": acc.photons, "grid": list(ph.grid.candela.shape),
              "symmetry": ph.grid.symmetry, "seconds": seconds,
              "ugr_4h8h_70_50_20": value, "ugr_4h8h_70_50_20_error": error}
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    print(f"demo, {acc.photons:,} photons, grid {ph.grid.symmetry} "
          f"{ph.grid.candela.shape[0]} x {ph.grid.candela.shape[1]}")
    for name, s in seconds.items():
        print(f"  {name:28s} {1000 * s:8.1f} ms")
    print(f"  UGR 4H 8H 70/50/20: {value:.2f} +- {error:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
