"""``lumitrace fit`` against a naive loop of whole ``lumitrace trace`` commands, side by side.

    python tools/fit_speed.py [--evaluations 96] [--photons 8192] [--max-photons 131072]
                              [--naive schedule fixed] [--target-photons 2e6]
                              [--confirm-photons 262144] [--out DIR] [--json]

The problem: the demo downlight with its diffuser deactivated (an open reflector: its beam
shows its reflector), whose reflector's roughness and reflectance and whose LED's height
were traced at 0.3, 0.85 and 46 mm (2M photons, seed 99): that LDT is the target, and both
searches start from the stage's own 0.15, 0.92 and 49.5 mm (ranges [0, 1], [0.5, 1] and
[40, 50] mm: above 50 mm the LED is inside its board).

- **fit**: ``lumitrace fit`` as a user runs it (a subprocess, ``--threads 2``), its whole
  process's CPU seconds; the CPU seconds of every evaluation are in its ``fit.json``
  (from the process's start).
- **naive**: the way one scripts it today: the same CMA-ES (``cma``, the same options and
  seed) in a Python loop that, for each candidate, writes its values as a layer and runs
  ``lumitrace trace STAGE --edits LAYER --photons N --seed 0 --no-pictures --no-sublayer
  --json`` (a subprocess: the ``lumitrace`` command), reads the LDT it wrote and computes
  the same merit from it. ``N`` follows the fit's photons generation by generation
  (``schedule``: the same photons per evaluation) or is the fit's last, fixed
  (``fixed``: what a loop without a schedule needs to resolve the end). Its CPU seconds
  are its commands' and its own loop's.

Both are judged alike, outside the timed work: after every generation the best candidate
so far (by its own search's merit) is traced with another seed (12345) and 2^18 photons,
and its merit there is the run's merit at that moment. The figures: CPU seconds until that
merit is within 1.5x of the true values' merit measured the same way (the noise floor),
and the merit reached at the end; evaluations per CPU hour and per wall-clock hour (2
cores). The machine is shared: CPU seconds compare, wall seconds less so.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: no spinning BLAS threads

import argparse
import json
import math
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "service"))

VARY = ["/Luminaire/Materials/ReflectorAluminium.lumitrace:roughness",
        "/Luminaire/Materials/ReflectorAluminium.lumitrace:specularReflectance=0.5:1",
        "/Luminaire/LED.xformOp:translate[2]=40:50"]
TRUTH = [0.3, 0.85, 46.0]
CONFIRM_PHOTONS = 1 << 18
CONFIRM_SEED = 12345
FLOOR_FACTOR = 1.5


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def own_cpu() -> float:
    return time.process_time()


def make_problem(folder: Path, photons: int) -> tuple[Path, Path]:
    """The open downlight (start) and the target LDT of its true values."""
    text = (ROOT / "stages" / "downlight.usda").read_text()
    marker = 'def Mesh "Diffuser" (\n'
    assert marker in text
    text = text.replace(marker, marker + "        active = false\n")
    stage = folder / "open.usda"
    stage.write_text(text)
    true = text.replace("float lumitrace:roughness = 0.15", "float lumitrace:roughness = 0.3") \
        .replace("float lumitrace:specularReflectance = 0.92",
                 "float lumitrace:specularReflectance = 0.85") \
        .replace("double3 xformOp:translate = (0, 0, 49.5)",
                 "double3 xformOp:translate = (0, 0, 46)")
    (folder / "true.usda").write_text(true)
    subprocess.run([sys.executable, "-m", "lumitrace.cli", "trace", str(folder / "true.usda"),
                    "--photons", str(photons), "--seed", "99", "--no-pictures", "--no-sublayer",
                    "--out", str(folder / "target"), "--quiet"], check=True)
    return stage, folder / "target" / "true.ldt"


class Judge:
    """The merit of candidate values traced with another seed and more photons (the same
    for both runs; cached by values)."""

    def __init__(self, stage: Path, target: Path, photons: int = CONFIRM_PHOTONS):
        from lumitrace.fit.candidates import CandidateStage
        from lumitrace.fit.measure import Plan
        from lumitrace.fit.objective import Objective
        from lumitrace.fit.parameters import resolve
        from lumitrace.fit.target import read_target

        self.cs = CandidateStage(stage)
        self.params = resolve(self.cs.stage, VARY)
        self.objective = Objective(read_target(target))
        self.plan = Plan.of(self.cs.scene(self.params, [p.start for p in self.params]),
                            CONFIRM_SEED)
        self.cache: dict[tuple, float] = {}
        self.photons = photons

    def __call__(self, values) -> float:
        from lumitrace.fit.measure import measurement, trace_counts

        key = tuple(round(float(v), 12) for v in values)
        if key not in self.cache:
            scene = self.cs.scene(self.params, list(values))
            acc, _ = trace_counts(scene, self.plan, self.photons)
            self.cache[key] = self.objective.merit(
                measurement(scene, acc, self.objective.needs)).merit
        return self.cache[key]


def run_fit(stage: Path, target: Path, out: Path, args) -> dict:
    before, t0 = children_cpu(), time.perf_counter()
    cmd = [sys.executable, "-m", "lumitrace.cli", "fit", str(stage), "--target", str(target),
           "--vary", *VARY, "--evaluations", str(args.evaluations), "--photons",
           str(args.photons), "--max-photons", str(args.max_photons), "--seed", "0",
           "--threads", "2", "--no-pictures", "--final-error", "0.05", "--out", str(out),
           "--json", "--fresh"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(done.stderr)
    cpu, wall = children_cpu() - before, time.perf_counter() - t0
    data = json.loads((out / "fit.json").read_text())
    gens = {}
    for e in data["evaluations_list"]:
        if e.get("mean"):
            continue
        gens.setdefault(e["generation"], []).append(e)
    trajectory, best = [], None
    for g in sorted(gens):
        for e in gens[g]:
            if best is None or e["photons"] > best["photons"] or (
                    e["photons"] == best["photons"] and e["merit"] < best["merit"]):
                best = e
        trajectory.append({"generation": g, "evaluations": gens[g][-1]["index"] + 1,
                           "cpu": gens[g][-1]["cpu_seconds"], "photons": gens[g][0]["photons"],
                           "best": best["values"]})
    return {"cpu": cpu, "wall": wall, "evaluations": data["evaluations"],
            "trajectory": trajectory, "photons": [t["photons"] for t in trajectory]}


def _layer(path: Path, values) -> None:
    """The candidate's values as a layer of overs (what a script would write)."""
    rough, spec, z = values
    path.write_text(f"""#usda 1.0
over "Luminaire"
{{
    over "Materials"
    {{
        over "ReflectorAluminium"
        {{
            float lumitrace:roughness = {rough!r}
            float lumitrace:specularReflectance = {spec!r}
        }}
    }}
    over "LED"
    {{
        double3 xformOp:translate = (0, 0, {z!r})
    }}
}}
""")


def run_naive(stage: Path, target: Path, out: Path, photons_of, args) -> dict:
    """The naive loop: CMA-ES (the same options as the fit's) over whole trace commands."""
    import cma
    import numpy as np

    from lumitrace.fit.objective import Measurement, Objective
    from lumitrace.fit.parameters import FitError
    from lumitrace.fit.search import SIGMA0, TOLX
    from lumitrace.fit.target import read_target

    objective = Objective(read_target(target))
    c_grid, _, _ = objective.match_grid()
    gammas = objective.gammas()
    lo = np.array([0.0, 0.5, 40.0])
    hi = np.array([1.0, 1.0, 50.0])
    start = np.array([0.15, 0.92, 49.5])
    es = cma.CMAEvolutionStrategy(list((start - lo) / (hi - lo)), SIGMA0,
                                  {"seed": 1, "verbose": -9, "tolx": TOLX, "tolfun": 0.0,
                                   "tolflatfitness": 10_000})

    def fold(x):
        t = np.fmod(np.abs(np.asarray(x, float)), 2.0)
        return lo + np.where(t > 1.0, 2.0 - t, t) * (hi - lo)

    out.mkdir(parents=True, exist_ok=True)
    before_c, before_o, t0 = children_cpu(), own_cpu(), time.perf_counter()
    trajectory, best, best_merit, n, g = [], None, math.inf, 0, 0
    while n < args.evaluations and not es.stop():
        xs = es.ask()
        photons = photons_of(g)
        merits = []
        for x in xs:
            values = [float(v) for v in fold(x)]
            _layer(out / "candidate.usda", values)
            subprocess.run([sys.executable, "-m", "lumitrace.cli", "trace", str(stage),
                            "--edits", str(out / "candidate.usda"), "--photons",
                            str(photons), "--seed", "0", "--no-pictures", "--no-sublayer",
                            "--out", str(out / "run"), "--json"],
                           check=True, capture_output=True)
            try:
                got = read_target(out / "run" / "open.ldt")  # the file a user reads
                cd = got.values(c_grid, gammas)
            except FitError:  # no light left the luminaire (the LED inside its board)
                cd = np.zeros((len(c_grid), len(gammas)))
            m = objective.merit(Measurement(cd, np.zeros_like(cd), {}, photons, 0.0)).merit
            merits.append(m)
            if m < best_merit or photons > (best or {}).get("photons", 0):
                best_merit, best = m, {"values": values, "photons": photons}
            n += 1
        es.tell(xs, merits)
        cpu = children_cpu() - before_c + own_cpu() - before_o
        trajectory.append({"generation": g, "evaluations": n, "cpu": cpu, "photons": photons,
                           "best": best["values"]})
        g += 1
    return {"cpu": children_cpu() - before_c + own_cpu() - before_o,
            "wall": time.perf_counter() - t0, "evaluations": n, "trajectory": trajectory}


def judged(run: dict, judge: Judge, level: float) -> dict:
    """The run's judged merit after each generation and its CPU seconds to ``level``."""
    reached = None
    for t in run["trajectory"]:
        t["judged"] = judge(t["best"])
        if reached is None and t["judged"] <= level:
            reached = t["cpu"]
    return {"cpu": run["cpu"], "wall": run["wall"], "evaluations": run["evaluations"],
            "cpu_to_floor": reached, "final_merit": run["trajectory"][-1]["judged"],
            "evaluations_per_cpu_hour": 3600 * run["evaluations"] / run["cpu"],
            "evaluations_per_hour": 3600 * run["evaluations"] / run["wall"],
            "trajectory": [{k: t[k] for k in ("generation", "evaluations", "cpu", "photons",
                                              "judged")} for t in run["trajectory"]]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--evaluations", type=int, default=96)
    ap.add_argument("--photons", type=int, default=8192)
    ap.add_argument("--max-photons", type=int, default=1 << 17)
    ap.add_argument("--naive", nargs="+", choices=("schedule", "fixed"),
                    default=["schedule", "fixed"])
    ap.add_argument("--target-photons", type=int, default=2_000_000,
                    help="photons of the target's trace (default 2e6)")
    ap.add_argument("--confirm-photons", type=int, default=CONFIRM_PHOTONS,
                    help="photons of the judging traces (default 2^18)")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    folder = args.out or Path(tempfile.mkdtemp(prefix="fit-speed-"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        stage, target = make_problem(folder, args.target_photons)
        judge = Judge(stage, target, args.confirm_photons)
        floor = judge(TRUTH)
        level = FLOOR_FACTOR * floor
        fit = run_fit(stage, target, folder / "fit", args)
        results = {"fit": judged(fit, judge, level)}
        schedule = fit["photons"]
        for kind in args.naive:
            photons_of = (lambda g: schedule[min(g, len(schedule) - 1)]) \
                if kind == "schedule" else (lambda g: schedule[-1])
            naive = run_naive(stage, target, folder / f"naive-{kind}", photons_of, args)
            results[f"naive_{kind}"] = judged(naive, judge, level)
        report = {"truth_merit": floor, "level": level, "runs": results}
        for kind in args.naive:
            a, b = results["fit"], results[f"naive_{kind}"]
            report[f"cpu_ratio_{kind}"] = b["cpu"] / a["cpu"]
            if a["cpu_to_floor"] and b["cpu_to_floor"]:
                report[f"cpu_to_floor_ratio_{kind}"] = b["cpu_to_floor"] / a["cpu_to_floor"]
        if args.json:
            print(json.dumps(report))
        else:
            print(f"noise floor: the true values' merit {floor:.4f} ({judge.photons:,} "
                  f"photons, seed {CONFIRM_SEED}); level {level:.4f}")
            for name, r in results.items():
                to = "not reached" if r["cpu_to_floor"] is None else \
                    f"{r['cpu_to_floor']:.1f} CPU s"
                print(f"{name:16s} {r['evaluations']:4d} evaluations, {r['cpu']:7.1f} CPU s "
                      f"({r['evaluations_per_cpu_hour']:,.0f}/CPU h, "
                      f"{r['evaluations_per_hour']:,.0f}/h), to the floor {to}, final merit "
                      f"{r['final_merit']:.4f}")
            for k, v in report.items():
                if k.startswith("cpu_"):
                    print(f"{k}: {v:.2f}")
    finally:
        if args.out is None:
            shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
