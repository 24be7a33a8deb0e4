"""Start-up of ``lumitrace trace``: time to the first photon, whole run and peak memory of a
small run, each in a fresh process, with the kernels' ahead-of-time build and with numba's
JIT (``LUMITRACE_KERNELS=jit``), interleaved, in one run.

    python tools/startup.py [--stage stages/reference/isotropic.usda] [--photons 1000]
                            [--repeats 5] [--json]

A child process is started as a user starts the CLI (``lumitrace trace STAGE --photons N
--no-pictures``); it notes the wall time, from just before the parent started it, at which
the emission kernel first returns (the first photons exist). Medians of ``--repeats``; the stage is traced from a
copy, into a temporary folder.

Then the whole process against the floor: the ``lumitrace`` command (without pictures; the
same stage run again with its read scene kept, no USD loaded; with
them, the solid drawn by the renderer it forks, as by default; drawn in its own process,
``LUMITRACE_RENDERER=inline``; and by a renderer in an interpreter of its own,
``LUMITRACE_RENDERER=process``) and ``python -c "import numpy; from pxr import Usd, UsdGeom, UsdLux, UsdShade"``
(no USD tool starts faster), in turn, each a fresh process timed from its start until it is
reaped, with its CPU seconds and peak resident memory from the kernel's accounting of the
child (``os.wait4``), after a first run of each that is not counted (Python's bytecode
cached, as an installed package has it); the ratios are taken pair by pair, medians given.
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


#: The floor: the imports a USD tool cannot start without.
FLOOR = "import numpy; from pxr import Usd, UsdGeom, UsdLux, UsdShade"
#: The ``lumitrace`` command as its console script runs it.
COMMAND = "import sys, lumitrace_launch; sys.exit(lumitrace_launch.main())"


def whole(cmd: list[str], cwd: Path, env: dict, terminal: bool = False) -> dict:
    """One command as a fresh process: wall seconds from its start until it is reaped, its
    CPU seconds (user + system) and peak resident memory (MB), as the kernel counted them;
    ``terminal``: its standard error a terminal (a pseudo-terminal read here), as a user
    at a terminal runs it."""
    import pty

    master, slave = pty.openpty() if terminal else (None, subprocess.PIPE)
    t = time.perf_counter()
    p = subprocess.Popen(cmd, cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                         stdout=subprocess.DEVNULL, stderr=slave)
    if terminal:
        os.close(slave)
        chunks = []
        while True:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the terminal's other side closed
                break
            if not chunk:
                break
            chunks.append(chunk)
        os.close(master)
        err = b"".join(chunks)
    else:
        err = p.stderr.read()
        p.stderr.close()
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode:
        raise SystemExit(f"{' '.join(cmd[:4])} ... failed:\n{err.decode(errors='replace')}")
    return {"wall_s": wall, "cpu_s": ru.ru_utime + ru.ru_stime, "peak_mb": ru.ru_maxrss / 1024}


def against_floor(stage: Path, photons: int, out: Path, repeats: int) -> dict:
    """Medians of the floor's, the plain run's and the run with pictures' figures, and of
    the ratios (run / floor) and differences (pictures - plain) taken run by run. Python's
    bytecode is cached (in a folder of its own) and each command run once first, as an
    installed package has it: where writing bytecode is turned off, every module would
    otherwise be compiled again in every process."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = str(out.parent / "bytecode")
    trace = [sys.executable, "-c", COMMAND, "trace", str(stage), "--photons", str(photons),
             "--out", str(out)]
    # the same stage run again, its read scene kept (lumitrace.stage.scene_cache): a copy
    # of its own saved a minute ago, whose results are not sublayered into it (a result
    # layer the stage reads changes at every run, and the scene is read again)
    kept = out.parent / "kept" / stage.name
    kept.parent.mkdir(exist_ok=True)
    shutil.copy(stage, kept)
    os.utime(kept, (time.time() - 60.0, time.time() - 60.0))
    cmds = {"floor": [sys.executable, "-c", FLOOR], "plain": trace + ["--no-pictures"],
            "kept": [sys.executable, "-c", COMMAND, "trace", str(kept), "--photons",
                     str(photons), "--out", str(out.parent / "kept_out"), "--no-pictures",
                     "--no-sublayer"],
            "pictures": trace, "terminal": trace, "inline": trace, "renderer": trace}
    # the solid drawn by the renderer the command forks (the default; at a terminal too,
    # where the command also draws its progress), in the command's own process, and by a
    # renderer in a new interpreter (a renderer's CPU is counted in the command's, as the
    # command waits for it; the peak is the larger process's)
    envs = {name: dict(env, LUMITRACE_RENDERER={"inline": "inline", "renderer": "process"}
                       .get(name, "auto")) for name in cmds}
    rows: dict[str, list] = {k: [] for k in cmds}
    for first in [True] + [False] * repeats:
        for name, cmd in cmds.items():
            shutil.rmtree(out, ignore_errors=True)
            figures = whole(cmd, stage.parent, envs[name], terminal=name == "terminal")
            if not first:
                rows[name].append(figures)
    med = lambda xs: statistics.median(xs)  # noqa: E731
    keys = ("wall_s", "cpu_s", "peak_mb")
    summary = {name: {k: med([r[k] for r in runs]) for k in keys} for name, runs in rows.items()}
    summary["plain_over_floor"] = {k: med([p[k] / f[k] for f, p in
                                            zip(rows["floor"], rows["plain"])]) for k in keys}
    summary["plain_minus_floor_mb"] = med([p["peak_mb"] - f["peak_mb"]
                                           for f, p in zip(rows["floor"], rows["plain"])])
    summary["kept_over_floor"] = {k: med([p[k] / f[k] for f, p in
                                           zip(rows["floor"], rows["kept"])]) for k in keys}
    for name in ("pictures", "terminal", "inline", "renderer"):
        summary[f"{name}_minus_plain"] = {k: med([q[k] - p[k] for p, q in
                                                  zip(rows["plain"], rows[name])])
                                          for k in keys}
    return summary


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
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / args.stage.name
        shutil.copy(args.stage, stage)
        summary["whole"] = against_floor(stage, args.photons, Path(tmp) / "out", args.repeats)
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
    w = summary["whole"]
    print("whole processes, in turn (medians; ratios and differences run by run):")
    for name, label in (("floor", "import floor"), ("plain", "--no-pictures"),
                        ("kept", "scene kept"),
                        ("pictures", "with pictures"), ("terminal", "at a terminal"),
                        ("inline", "drawn in-process"),
                        ("renderer", "a new renderer")):
        s = w[name]
        print(f"  {label:>14s}: {s['wall_s']:.2f} s wall, {s['cpu_s']:.2f} CPU s, "
              f"peak {s['peak_mb']:.0f} MB")
    r = w["plain_over_floor"]
    print(f"  --no-pictures / floor: {r['wall_s']:.2f} wall, {r['cpu_s']:.2f} CPU, "
          f"+{w['plain_minus_floor_mb']:.0f} MB")
    r = w["kept_over_floor"]
    print(f"  the same stage again, its scene kept, / floor: {r['wall_s']:.2f} wall, "
          f"{r['cpu_s']:.2f} CPU, {r['peak_mb']:.2f} of its memory")
    for key, label in (("pictures_minus_plain", "pictures (forked renderer) - none"),
                       ("terminal_minus_plain", "the same at a terminal - none"),
                       ("inline_minus_plain", "pictures drawn in-process - none"),
                       ("renderer_minus_plain", "pictures by a new renderer - none")):
        d = w[key]
        print(f"  {label}: +{d['wall_s']:.2f} s wall, +{d['cpu_s']:.2f} CPU s, "
              f"+{d['peak_mb']:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
