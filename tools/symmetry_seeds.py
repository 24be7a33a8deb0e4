"""Which symmetry a stage's files get at a target, seed after seed, and whether its beam
angles hold against a long run.

Each seed runs as ``lumitrace trace STAGE --target-error E`` stops (the files' target); the
table gives per seed the photons, the symmetry and why, the files' judged error, and the
C0-C180 and C90-C270 beam angles with their stated errors, and how many of those errors
each lies from a reference run of ``--reference-photons`` (same engine, another seed).

    python tools/symmetry_seeds.py stages/louvre.usda [--seeds 20] [--target 0.02]
           [--reference-photons 64000000]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "service"))

BEAMS = ("beam_angle_c0_c180", "beam_angle_c90_c270")


def run_one(stage: str, seed: int, photons: int | None, target: float | None) -> dict:
    from lumitrace.photometry.distribution import files_accuracy, photometry_of
    from lumitrace.run.session import TraceSettings, run
    from lumitrace.stage.reader import read_stage

    scene = read_stage(stage)
    settings = TraceSettings(photons=photons, target_error=target, seed=seed,
                             resolution=16, threads=2)
    r = run(scene, settings)
    ph = photometry_of(scene, r.accumulator)
    acc = files_accuracy(scene, r.accumulator, ph)
    return {"photons": r.photons, "symmetry": ph.grid.symmetry,
            "source": ph.symmetry.source, "settled": ph.symmetry.settled,
            "judged": acc.error, **{k: getattr(ph.figures, k) for k in BEAMS},
            **{k + "_error": getattr(ph.figures, k + "_error") for k in BEAMS}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stage")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--target", type=float, default=0.02)
    ap.add_argument("--reference-photons", type=int, default=64_000_000)
    args = ap.parse_args(argv)
    stage = Path(args.stage)
    if not stage.exists():  # a path in the checkout, from anywhere
        stage = Path(__file__).resolve().parents[1] / args.stage
    args.stage = str(stage)
    ref = run_one(args.stage, 1000, args.reference_photons, None)
    print(f"reference: {ref['photons']:,} photons, {ref['symmetry']} ({ref['source']}), "
          + ", ".join(f"{k} {ref[k]:.2f} +- {ref[k + '_error']:.2f}" for k in BEAMS))
    print("| seed | photons | symmetry (why) | files' error | beam C0-C180 | z | "
          "beam C90-C270 | z |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    worst, rotational = 0.0, 0
    for seed in range(args.seeds):
        r = run_one(args.stage, seed, None, args.target)
        rotational += r["symmetry"] == "rotational"
        cells = []
        for k in BEAMS:
            v, e = r[k], r[k + "_error"]
            if v is None or ref[k] is None:
                cells += ["-", ""]
                continue
            z = (v - ref[k]) / (e ** 2 + (ref[k + "_error"] or 0.0) ** 2) ** 0.5
            worst = max(worst, abs(z))
            cells += [f"{v:.2f} +- {e:.2f}", f"{z:+.2f}"]
        print(f"| {seed} | {r['photons']:,} | {r['symmetry']} ({r['source']}"
              f"{'' if r['settled'] else ', open'}) | {r['judged']:.2%} | "
              + " | ".join(cells) + " |")
    print(f"\nrotational in {rotational} of {args.seeds} seeds; largest |z| {worst:.2f} "
          "(the combined error of the run and the reference)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
