#!/usr/bin/env python
"""Stress the write path: signals at random moments of many runs, and bursts of
concurrent runs, on a copy of a stage; prints how many runs ended in each state.

Every run is checked afterwards: the folder must hold one complete set of outputs (one
run id in the EXR, IES, LDT and result layer), no staging leftovers, and the stage must
hold exactly the one sublayer entry (no stage edit lost or doubled).

Usage::

    python tools/publish_stress.py                    # 40 signalled runs, 5 bursts of 3
    python tools/publish_stress.py --runs 200 --bursts 20 --seconds 1800
"""
from __future__ import annotations

import argparse
import collections
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _cmd(stage: Path, seed: int) -> list[str]:
    return [sys.executable, "-m", "lumitrace.cli", "trace", str(stage), "--photons", "60000",
            "--resolution", "16", "--seed", str(seed), "--no-progress", "--threads", "1"]


def consistent(folder: Path, name: str) -> str | None:
    """The run id of the one complete set in ``folder``, or None when it is mixed."""
    from lumitrace.publish.runs import published_run_ids

    ids = published_run_ids(folder, name)
    leftovers = [p for p in folder.iterdir()
                 if p.name.startswith(f".{name}") and not p.name.endswith(".lock")]
    if len(set(ids.values())) != 1 or None in ids.values() or leftovers:
        return None
    return ids["exr"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stage", type=Path, default=ROOT / "stages/reference/lambertian_disc.usda")
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--bursts", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=900.0, help="stop after this long")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    rnd = random.Random(args.seed)
    t_end = time.monotonic() + args.seconds
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / "lamp.usda"
        shutil.copy(args.stage, stage)
        t0 = time.perf_counter()
        subprocess.run(_cmd(stage, 0), capture_output=True, check=True)
        total = time.perf_counter() - t0
        entry = stage.read_text().count("lamp.lumitrace.usda")
        states = collections.Counter()
        for k in range(args.runs):
            if time.monotonic() > t_end:
                break
            before = consistent(stage.parent, "lamp")
            p = subprocess.Popen(_cmd(stage, k + 1), stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True)
            time.sleep(rnd.uniform(0.2, 1.1) * total)
            p.send_signal(rnd.choice(SIGNALS))
            p.communicate(timeout=300)
            after = consistent(stage.parent, "lamp")
            if after is None:
                states["MIXED SET"] += 1
            elif after == before:
                states["interrupted: earlier set kept"] += 1
            else:
                states["new set published"] += 1
            if stage.read_text().count("lamp.lumitrace.usda") != entry:
                states["STAGE EDIT LOST OR DOUBLED"] += 1
        for _ in range(args.bursts):
            if time.monotonic() > t_end:
                break
            procs = [subprocess.Popen(_cmd(stage, rnd.randrange(1 << 30)),
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE)
                     for _ in range(3)]
            codes = [p.wait(timeout=600) for p in procs]
            ok = consistent(stage.parent, "lamp") is not None and codes == [0, 0, 0]
            states["burst of 3 concurrent runs: one complete set" if ok
                   else "BURST FAILED"] += 1
    width = max(len(s) for s in states) if states else 10
    print(f"{'outcome':{width}s}  runs")
    for state, n in sorted(states.items()):
        print(f"{state:{width}s}  {n}")
    bad = sum(n for s, n in states.items() if s.isupper() or s.startswith(("MIXED", "STAGE", "BURST")))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
