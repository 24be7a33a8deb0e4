"""Start-up of ``lumitrace trace``: time to the first photon, whole run and peak memory of a
small run, each in a fresh process, with the kernels' ahead-of-time build and with numba's
JIT (``LUMITRACE_KERNELS=jit``), interleaved, in one run.

    python tools/startup.py [--stage stages/reference/isotropic.usda] [--photons 1000]
                            [--repeats 5] [--json]

A child process is started as a user starts the CLI (``lumitrace trace STAGE --photons N
--no-pictures``); it notes the wall time, from just before the parent started it, at which
the emission kernel first returns (the first photons exist). Medians of ``--repeats``; the stage is traced from a
copy, into a temporary folder.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = """
import resource, sys, time
launched = float(sys.argv[1])
from lumitrace import cli
from lumitrace.trace import compiled
first = []
call = type(compiled.emit_photons).__call__
class Noted(type(compiled.emit_photons)):
    def __call__(self, *args):
        out = call(self, *args)
        if not first:
            first.append(time.time() - launched)
        return out
compiled.emit_photons.__class__ = Noted
sys.argv = ["lumitrace", "trace"] + sys.argv[2:]
try:
    cli.main()
except SystemExit:
    pass
print({"first_photon_s": first[0], "run_s": time.time() - launched,
       "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
       "backend": compiled.backend(), "numba_loaded": "numba" in sys.modules},
      file=sys.stderr)
"""


def one(stage: Path, photons: int, out: Path, jit: bool) -> dict:
    """One fresh ``lumitrace trace`` process's figures."""
    env = dict(os.environ)
    env.pop("LUMITRACE_KERNELS", None)
    if jit:
        env["LUMITRACE_KERNELS"] = "jit"
    shutil.rmtree(out, ignore_errors=True)
    launched = time.time()
    p = subprocess.run([sys.executable, "-c", CHILD, repr(launched), str(stage), "--photons",
                        str(photons), "--out", str(out), "--no-pictures", "--no-sublayer"],
                       env=env, capture_output=True, text=True)
    if p.returncode:
        raise SystemExit(p.stderr)
    import ast

    return ast.literal_eval(p.stderr.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stage", type=Path, default=ROOT / "stages/reference/isotropic.usda")
    ap.add_argument("--photons", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    rows: dict[str, list] = {"aot": [], "jit": []}
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / args.stage.name
        shutil.copy(args.stage, stage)
        for _ in range(args.repeats):
            for name in rows:
                rows[name].append(one(stage, args.photons, Path(tmp) / "out", name == "jit"))
    summary = {}
    for name, runs in rows.items():
        summary[name] = {k: statistics.median(r[k] for r in runs)
                         for k in ("first_photon_s", "run_s", "peak_mb")}
        summary[name]["backend"] = runs[0]["backend"]
        summary[name]["numba_loaded"] = runs[0]["numba_loaded"]
    summary["ratio_first_photon"] = (summary["aot"]["first_photon_s"]
                                     / summary["jit"]["first_photon_s"])
    if args.json:
        print(json.dumps(summary, indent=1))
        return 0
    print(f"{args.stage.name}, {args.photons:,} photons, median of {args.repeats}:")
    for name in rows:
        s = summary[name]
        print(f"  kernels from {s['backend']:3s}: first photon {s['first_photon_s']:.2f} s, "
              f"run {s['run_s']:.2f} s, peak {s['peak_mb']:.0f} MB"
              f"{' (numba loaded)' if s['numba_loaded'] else ''}")
    print(f"  first photon, ahead-of-time / JIT: {summary['ratio_first_photon']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
