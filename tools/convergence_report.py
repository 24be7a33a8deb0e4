#!/usr/bin/env python3
"""Convergence reports for every reference stage and a summary table of time-to-error.

    python tools/convergence_report.py [--seconds 40] [--out reports/] [--resolution 64]

Stages with a closed form are compared with it; the paraboloid (no closed form for its
map) with a long run traced first (``--reference-photons``). Prints, per stage and filter
threshold, the time the map needs to reach 5% and 2% relative RMS error and the speed-up
of the filtered map over the raw one, measured in the same run.
"""
from __future__ import annotations

import argparse
import os
import shutil
from pathlib import Path

from lumitrace.report.convergence_report import REPORT_THRESHOLDS, ReportSettings, run_report

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("isotropic", "lambertian_disc", "fresnel_slab", "paraboloid")


def long_run_reference(stage: Path, folder: Path, photons: int, resolution: int) -> Path:
    """Trace a copy of ``stage`` with many photons, unfiltered; return its EXR."""
    from lumitrace.publish.outputs import write_outputs
    from lumitrace.run.session import TraceSettings, run
    from lumitrace.stage.reader import read_stage

    copy = folder / f"{stage.stem}_reference.usda"
    shutil.copy(stage, copy)
    result = run(read_stage(copy), TraceSettings(photons=photons, resolution=resolution,
                                                 threshold=0.0, seed=12345))
    return Path(write_outputs(result, folder)["intensity_map"])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=40.0)
    p.add_argument("--resolution", type=int, default=64)
    p.add_argument("--out", type=Path, default=ROOT / "reports")
    p.add_argument("--reference-photons", type=int, default=60_000_000)
    p.add_argument("--thresholds", default=",".join(f"{t:g}" for t in REPORT_THRESHOLDS))
    a = p.parse_args()
    thresholds = tuple(float(x) for x in a.thresholds.split(","))
    settings = ReportSettings(seconds=a.seconds, resolution=a.resolution, thresholds=thresholds,
                              threads=os.cpu_count() or 1)
    lines = ["| stage | map | time to 5% | time to 2% | speed-up 5% | speed-up 2% |",
             "| --- | --- | --- | --- | --- | --- |"]
    for name in STAGES:
        stage = ROOT / "stages" / "reference" / f"{name}.usda"
        out = a.out / name
        out.mkdir(parents=True, exist_ok=True)
        ref = None
        if name == "paraboloid":
            ref = long_run_reference(stage, out, a.reference_photons, a.resolution)
        data = run_report(stage, out, settings, ref)["data"]
        for key, c in data["time_to_error"].items():
            sp = data["speedup_filtered_over_raw"].get(key, {})
            fmt = lambda t: f"{t:.3g} s" if t else "not reached"  # noqa: E731
            spf = lambda v: f"{v:.1f}x" if v else "-"  # noqa: E731
            lines.append(f"| {name} | {'raw' if key == '0' else 'threshold ' + key} | "
                         f"{fmt(c['0.05'])} | {fmt(c['0.02'])} | {spf(sp.get('0.05'))} | "
                         f"{spf(sp.get('0.02'))} |")
        print(f"{name}: {out / 'index.html'}", flush=True)
    table = "\n".join(lines)
    (a.out / "summary.md").write_text(table + "\n")
    print(table)


if __name__ == "__main__":
    main()
