"""Do the peak, beam angles and nadir hold over many seeds? Their mean against the closed form
(within its standard error of the mean), their spread against their stated errors.

    python tools/seed_study.py [--seeds 20] [--photons 2000000] [--stages lambertian_disc mirror_cup louvre]

Each seed traces a stage and measures its photometry as the files do. Printed per stage and
figure: the mean over the seeds with its standard error, the closed form where there is one
(reference stages: ``*.expected.json``), the bias in percent and in standard errors of the
mean, and the ratio of the seeds' standard deviation to the mean stated error (1 where the
errors are honest). For the beam angles also how often each count of crossings occurs.
"""
from __future__ import annotations

import argparse
import collections
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from lumitrace.photometry.distribution import photometry_of
from lumitrace.report.references import expected_intensity, read_expectation
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ("peak_intensity", "beam_angle_c0_c180", "beam_angle_c90_c270",
           "field_angle_c0_c180", "nadir")


def _stage(name: str) -> Path:
    for folder in (ROOT / "stages" / "reference", ROOT / "stages"):
        if (folder / f"{name}.usda").exists():
            return folder / f"{name}.usda"
    raise SystemExit(f"no stage named {name!r} in stages/ or stages/reference/")


def _truth(stage: Path) -> dict:
    """Closed-form peak, beam and field angles and nadir of a reference stage with a
    closed-form distribution (empty otherwise): from its intensity on a fine gamma raster
    (axis down: gamma from nadir), the nadir as the mean over the files' polar cap."""
    try:
        exp = read_expectation(stage)
        gamma = np.radians(np.linspace(0.0, 180.0, 720001))
        d = np.stack([np.sin(gamma), np.zeros_like(gamma), -np.cos(gamma)], axis=1)
        prof = expected_intensity(exp, d)
    except (KeyError, ValueError):
        return {}
    peak = float(prof.max())
    out = {"peak_intensity": peak}
    for key, level in (("beam_angle_c0_c180", 0.5), ("field_angle_c0_c180", 0.1)):
        above = np.flatnonzero(prof >= level * peak)
        if above[-1] < len(prof) - 1:
            out[key] = 2.0 * float(np.degrees(gamma[above[-1]]))
    out["beam_angle_c90_c270"] = out.get("beam_angle_c0_c180")
    return out


def _cap_mean(stage: Path, half_angle: float) -> float:
    """Closed-form mean intensity (cd) over the polar cap at nadir of ``half_angle`` deg."""
    g = np.radians(np.linspace(0.0, half_angle, 2001))
    d = np.stack([np.sin(g), np.zeros_like(g), -np.cos(g)], axis=1)
    w = np.sin(g)
    return float((expected_intensity(read_expectation(stage), d) * w).sum() / w.sum())


def study(name: str, seeds: int, photons: int, threads: int) -> list[str]:
    stage = _stage(name)
    scene = read_stage(stage)
    values = collections.defaultdict(list)
    errors = collections.defaultdict(list)
    crossings = collections.Counter()
    caps = []
    t0 = time.perf_counter()
    for seed in range(seeds):
        result = run(scene, TraceSettings(photons=photons, resolution=8, seed=1000 + seed,
                                          threads=threads))
        ph = photometry_of(result.scene, result.accumulator)
        f = ph.figures
        for key in FIGURES[:-1]:
            v, e = getattr(f, key), getattr(f, key + "_error")
            if v is not None and e is not None:
                values[key].append(v)
                errors[key].append(e)
        values["nadir"].append(float(ph.grid.candela[0, 0]))
        errors["nadir"].append(float(ph.grid.sigma[0, 0]))
        crossings[len(f.beam_crossings_c0_c180)] += 1
        caps.append(ph.grid.pole_caps[0])
    truth = _truth(stage)
    if truth:  # the nadir value is the mean over its polar cap (its width may vary by seed)
        truth["nadir"] = float(np.mean([_cap_mean(stage, c) for c in caps]))
    lines = [f"{name}: {seeds} seeds of {photons:,} photons ({time.perf_counter() - t0:.0f} s); "
             f"beam C0-C180 crossings per seed: {dict(sorted(crossings.items()))}"]
    for key in FIGURES:
        v, e = np.array(values[key]), np.array(errors[key])
        if len(v) < 2:
            lines.append(f"  {key:22s} undefined")
            continue
        mean, sem = float(v.mean()), float(v.std(ddof=1) / math.sqrt(len(v)))
        honesty = float(v.std(ddof=1) / e.mean()) if e.mean() > 0 else math.nan
        line = (f"  {key:22s} mean {mean:9.3f} +- {sem:7.3f} (sd/stated error {honesty:4.2f},"
                f" {len(v)} seeds)")
        t = truth.get(key)
        if t is not None:
            line += (f"  closed form {t:9.3f}: bias {100 * (mean - t) / t:+.2f}% = "
                     f"{(mean - t) / sem:+.1f} SEM")
        lines.append(line)
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--photons", type=int, default=2_000_000)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--stages", nargs="+", default=["lambertian_disc", "mirror_cup", "louvre"])
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    for name in a.stages:
        print("\n".join(study(name, a.seeds, a.photons, a.threads)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
