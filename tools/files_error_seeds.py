"""Is the files' stated error the error they have? Over many seeds, the relative RMS error
the photometric files state (``photometry_error``) against their true error from the closed
form, on the side-by-side scenes that have one.

    python tools/files_error_seeds.py [--seeds 40] [--photons 98304] [--target-error E]
                                      [--scenes lambertian mirror_cup isotropic] [--json]

Each seed traces the scene (``--photons``, or until the files reach ``--target-error`` as the
command stops, the stopping rule included) and measures the files' grid as they are written.
Printed per scene: the photons (median), the stated error's mean, the true error's RMS over
the stated one's (1 where the statement is honest: a single run's true error is above its
stated one about half the time, as a standard error's is), how often the true error is
above the stated one, and the mean squared z-score of the grid's values against the closed
form's cell means over their standard errors (1 where every sigma is honest).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from side_by_side import build, grid_true_error

from lumitrace.photometry.accuracy import grid_accuracy
from lumitrace.photometry.distribution import C_STEP, photometry_of
from lumitrace.report.references import read_expectation
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage


def seed_errors(stage: Path, seeds: int, photons: int, target: float | None) -> dict:
    """Per seed: photons, stated RMS error, true RMS error, mean squared z of the values."""
    scene = read_stage(stage)
    expectation = read_expectation(stage)
    rows = []
    for seed in range(1, seeds + 1):
        settings = TraceSettings(target_error=target, seed=seed) if target else \
            TraceSettings(photons=photons, seed=seed)
        acc = run(scene, settings).accumulator
        grid = photometry_of(scene, acc).grid
        true, z = grid_true_error(expectation, scene.up_axis, grid)
        rows.append((acc.photons, grid_accuracy(grid, C_STEP).rms, true,
                     float(np.nanmean(z ** 2))))
    a = np.array(rows)
    return {"seeds": seeds, "photons_median": float(np.median(a[:, 0])),
            "stated_mean": float(a[:, 1].mean()), "true_mean": float(a[:, 2].mean()),
            "true_over_stated_rms": math.sqrt(float((a[:, 2] ** 2).mean())
                                              / float((a[:, 1] ** 2).mean())),
            "true_above_stated": int((a[:, 2] > a[:, 1]).sum()),
            "mean_z2": float(a[:, 3].mean())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--photons", type=int, default=98_304)
    ap.add_argument("--target-error", type=float, default=None)
    ap.add_argument("--scenes", nargs="+", default=["lambertian", "mirror_cup", "isotropic"],
                    choices=["lambertian", "mirror_cup", "isotropic"])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenes:
            r = out[name] = seed_errors(build(name, Path(tmp)), args.seeds, args.photons,
                                        args.target_error)
            if not args.json:
                print(f"{name}: {r['seeds']} seeds, {r['photons_median']:,.0f} photons "
                      f"(median); stated {r['stated_mean']:.2%} (mean), true over stated "
                      f"(RMS) {r['true_over_stated_rms']:.3f}, true above stated in "
                      f"{r['true_above_stated']} of {r['seeds']}; mean z^2 "
                      f"{r['mean_z2']:.3f}", flush=True)
    if args.json:
        print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
