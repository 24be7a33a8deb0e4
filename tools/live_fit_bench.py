"""A fit started from the live view against the same fit as a command, side by side.

    python tools/live_fit_bench.py [--repeats 5] [--evaluations 40] [--photons 16384]
                                   [--target-photons 1000000]

The problem: the reference mirror cup with its mirror at reflectance 0.7, fitted to its own
LDT traced at 0.95 (``--target-photons``, seed 99), the reflectance varied over [0.5, 1]. In each
repeat, in turn:

- **command**: ``lumitrace fit STAGE --target LDT --vary ... --evaluations N --photons P
  --final-error 0.05 --no-pictures --threads 2 --fresh --json``, a subprocess, its wall
  seconds from its start to its exit;
- **live view**: ``POST /fit`` with the same request to a ``lumitrace serve`` of the same
  stage (started before the repeat and idle: its own trace done), its wall seconds from
  the request to the ``done`` state.

Printed: each one's median, and the median of the repeats' ratios (live / command): what
a fit costs more for being started from the page (its process's start, the service's
idle work beside it).
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from service_process import Service  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

REFLECTANCE = "/Luminaire/Materials/Mirror.lumitrace:specularReflectance"


def _post(url: str, body: dict) -> dict:
    req = urllib.request.Request(url, json.dumps(body).encode(), method="POST",
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req) as r:
        return json.loads(r.read())


def problem(folder: Path, photons: int) -> tuple[Path, Path]:
    """The stage (reflectance 0.7) and its target LDT (0.95)."""
    from lumitrace.publish.outputs import write_outputs
    from lumitrace.run.session import run
    from lumitrace.run.settings import TraceSettings
    from lumitrace.stage.reader import read_stage

    truth = mirror_cup(folder / "truth.usda", 0.95)
    result = run(read_stage(truth), TraceSettings(photons=photons, seed=99, threads=2))
    ldt = Path(write_outputs(result, folder / "target", sublayer=False, pictures=False)["ldt"])
    return mirror_cup(folder / "cup.usda", 0.7), ldt


def mirror_cup(path: Path, reflectance: float) -> Path:
    """The reference mirror cup at ``path``, its mirror reflecting ``reflectance``."""
    text = (ROOT / "stages" / "reference" / "mirror_cup.usda").read_text()
    old = "float lumitrace:specularReflectance = 0.95"
    assert old in text
    path.write_text(text.replace(old, f"float lumitrace:specularReflectance = {reflectance!r}"))
    return path


def command(stage: Path, ldt: Path, out: Path, args) -> float:
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "lumitrace.cli", "fit", str(stage), "--target",
                    str(ldt), "--vary", f"{REFLECTANCE}=0.5:1", "--evaluations",
                    str(args.evaluations), "--photons", str(args.photons), "--final-error",
                    "0.05", "--no-pictures", "--threads", "2", "--fresh", "--json",
                    "--out", str(out)], check=True, capture_output=True)
    return time.perf_counter() - t


def live(service: Service, ldt: Path, args) -> float:
    t = time.perf_counter()
    started = _post(service.url + "fit", {
        "target": {"name": ldt.name, "text": ldt.read_text(encoding="latin-1")},
        "vary": [f"{REFLECTANCE}=0.5:1"], "evaluations": args.evaluations,
        "photons": args.photons, "final_error": 0.05})
    service.wait_event(lambda e: e.kind == "fit" and e.data["fit"] == started["fit"]
                       and e.data["state"] in ("done", "failed"), timeout=600)
    seconds = time.perf_counter() - t
    with urllib.request.urlopen(service.url + "fit") as r:
        if json.loads(r.read())["state"] != "done":
            raise RuntimeError("the live fit failed")
    return seconds


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--evaluations", type=int, default=40)
    ap.add_argument("--photons", type=int, default=16384)
    ap.add_argument("--target-photons", type=int, default=1_000_000)
    args = ap.parse_args(argv)
    folder = Path(tempfile.mkdtemp(prefix="live-fit-bench-"))
    stage, ldt = problem(folder, args.target_photons)
    runs = {"command": [], "live": []}
    with Service(stage, "--photons", "40000", "--threads", "2",
                 "--out", folder / "served") as service:
        service.wait_done(0, pictures=False)
        for k in range(args.repeats):
            runs["command"].append(command(stage, ldt, folder / f"cli-{k}", args))
            runs["live"].append(live(service, ldt, args))
    ratios = [a / b for a, b in zip(runs["live"], runs["command"])]
    print(f"command: median {statistics.median(runs['command']):.2f} s; live view: "
          f"median {statistics.median(runs['live']):.2f} s; live / command, median of "
          f"{args.repeats} pairs: {statistics.median(ratios):.2f} "
          f"({min(ratios):.2f}-{max(ratios):.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
