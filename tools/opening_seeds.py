"""The luminous opening over seeds: its length and width against the truth (the Lambertian
disc's 100 mm) or a run of many photons, and its stated standard errors against their
spread (mean squared z-score; 1 where the errors are honest).

    python tools/opening_seeds.py [--seeds 20] [--photons 65536] [--json]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "service"))

from lumitrace.photometry.opening import measured_opening  # noqa: E402
from lumitrace.run import session  # noqa: E402,F401  (lends the opening its tracer)
from lumitrace.stage.reader import read_stage  # noqa: E402

#: Stages and their truths (length, width in m; None: a run of many photons).
STAGES = {"disc": ("stages/reference/lambertian_disc.usda", (0.1, 0.1)),
          "demo": ("stages/downlight.usda", None),
          "louvre": ("stages/louvre.usda", None)}


def study(name: str, seeds: int, photons: int, reference_photons: int) -> dict:
    path, truth = STAGES[name]
    scene = read_stage(ROOT / path)
    if truth is None:
        ref = measured_opening(scene, reference_photons, seed=10_000)
        truth = (ref.length, ref.width)
    runs = [measured_opening(scene, photons, seed=s) for s in range(seeds)]
    v = np.array([(o.length, o.width) for o in runs])
    e = np.array([o.error[:2] for o in runs])
    z = (v - np.asarray(truth)) / e
    return {"stage": name, "photons": photons, "seeds": seeds,
            "truth_mm": [1000 * t for t in truth],
            "mean_mm": (1000 * v.mean(axis=0)).tolist(),
            "mean_offset_pct": (100 * (v.mean(axis=0) / np.asarray(truth) - 1)).tolist(),
            "spread_mm": (1000 * v.std(axis=0, ddof=1)).tolist(),
            "stated_mm": (1000 * e.mean(axis=0)).tolist(),
            "mean_z2": (z ** 2).mean(axis=0).tolist(),
            "round": sorted({o.round for o in runs}), "sources": sorted({o.source for o in runs})}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--photons", type=int, default=1 << 16)
    ap.add_argument("--reference-photons", type=int, default=1 << 20)
    ap.add_argument("--stages", nargs="*", default=list(STAGES))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = [study(n, args.seeds, args.photons, args.reference_photons) for n in args.stages]
    if args.json:
        print(json.dumps(rows))
        return 0
    print(f"{'stage':8s} {'truth mm':>20s} {'mean mm':>20s} {'offset %':>16s} "
          f"{'spread mm':>16s} {'stated mm':>16s} {'mean z^2':>12s}")
    for r in rows:
        f = lambda xs, p=3: " ".join(f"{x:.{p}f}" for x in xs)  # noqa: E731
        print(f"{r['stage']:8s} {f(r['truth_mm']):>20s} {f(r['mean_mm']):>20s} "
              f"{f(r['mean_offset_pct'], 3):>16s} {f(r['spread_mm']):>16s} "
              f"{f(r['stated_mm']):>16s} {f(r['mean_z2'], 2):>12s}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
