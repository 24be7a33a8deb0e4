"""What the deliverables add to a run of the demo stage: the datasheet's HTML page and PDF,
the L3D geometry and the GLDF container, timed one by one and all together
(``write_deliverables``), and ``write_outputs`` with and without them; median wall seconds
of the repeats, after one warm-up (the first call in a process also imports matplotlib).

    python tools/deliverables_cost.py [--photons 2000000] [--repeats 5] [--no-pictures] [--json]
"""
from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "service"))

from lumitrace.photometry.distribution import photometry_of  # noqa: E402
from lumitrace.publish.datasheet import DatasheetInput, curve_pngs, datasheet_html  # noqa: E402
from lumitrace.publish.datasheet_pdf import datasheet_pdf  # noqa: E402
from lumitrace.publish.deliverables import write_deliverables  # noqa: E402
from lumitrace.publish.l3d import l3d_bytes  # noqa: E402
from lumitrace.publish.outputs import write_outputs  # noqa: E402
from lumitrace.run.session import TraceSettings, run  # noqa: E402
from lumitrace.stage.reader import read_stage  # noqa: E402

#: The record's output keys the deliverables read or write.
KEYS = ("ldt", "ies", "photometric_solid", "polar_diagram", "datasheet_html",
        "datasheet_pdf", "gldf")


def _median(fn, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(max(repeats, 1)):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=float, default=2e6)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-pictures", action="store_true",
                    help="write the outputs without the polar curve and the solid")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    pictures = not args.no_pictures
    scene = read_stage(ROOT / "stages" / "downlight.usda")
    result = run(scene, TraceSettings(photons=int(args.photons), threads=2))
    ph = photometry_of(scene, result.accumulator)
    folder = Path(tempfile.mkdtemp(prefix="lumitrace-deliverables-"))
    try:
        record = write_outputs(result, folder / "out", sublayer=False, pictures=pictures,
                               deliverables=True)
        final = {k: Path(record[k]) for k in KEYS if record[k]}
        staged = {k: folder / "staged" / v.name for k, v in final.items()}
        staged["ldt"].parent.mkdir()
        for k, v in final.items():
            shutil.copy(v, staged[k])
        polar = final["polar_diagram"].read_bytes() if "polar_diagram" in final else None
        data = DatasheetInput(record, ph.grid, scene.info,
                              final["photometric_solid"].read_bytes()
                              if "photometric_solid" in final else None)
        parts = {
            "datasheet_html": lambda: datasheet_html(
                data, {"polar": polar} if polar else curve_pngs(data)),
            "datasheet_pdf": lambda: datasheet_pdf(data),
            "l3d": lambda: l3d_bytes(scene, ph.opening, data.name),
            "all (write_deliverables)": lambda: write_deliverables(scene, ph, record, staged,
                                                                   final),
            "write_outputs without": lambda: write_outputs(
                result, folder / "out", sublayer=False, pictures=pictures),
            "write_outputs with": lambda: write_outputs(
                result, folder / "out", sublayer=False, pictures=pictures, deliverables=True),
        }
        seconds = {name: _median(fn, args.repeats) for name, fn in parts.items()}
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    report = {"photons": result.accumulator.photons, "pictures": pictures,
              "seconds": seconds,
              "added": seconds["write_outputs with"] - seconds["write_outputs without"]}
    if args.json:
        print(json.dumps(report))
    else:
        for name, s in seconds.items():
            print(f"{name:28s} {s:7.3f} s")
        print(f"{'added to write_outputs':28s} {report['added']:7.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
