"""The performance page's table: current figures, measured in one run on this machine.

    python tools/performance_page.py [--pairs 15] [--bench-seconds 5]
                                     [--page docs/explanation/performance.md] [--dry-run]
                                     [--quick]

Measured, each as whole processes started as a user starts them:

- the README's demo command (``lumitrace trace stages/downlight.usda --target-error 0.02
  --out results --no-sublayer``): its wall time, CPU time (user and system, its picture
  renderer included) and peak memory, the medians of ``--pairs`` runs;
- what each start-up mechanism saves on that command: the command run with the mechanism
  turned off and as it is, in turn (A B A B ...), ``--pairs`` pairs, the median of the
  pairs' CPU and wall ratios (a ratio taken pair by pair holds while the machine's speed
  drifts); a mechanism is turned off by a small driver that patches it out before the
  command starts (:data:`MECHANISMS`);
- ``lumitrace bench``: the tracer's path segments per second over bare Embree's rays per
  second on the very same rays;
- photons per CPU second of a 4M-photon run of the isotropic source.

The table replaces the page's text between its two ``performance-page`` markers;
``--dry-run`` prints it and writes nothing. ``--quick`` goes through every step in seconds
(a 1000-photon isotropic source stands in for the demo): a check that the tool runs, not a
measurement.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "explanation" / "performance.md"
START, END = "<!-- performance-page:start -->", "<!-- performance-page:end -->"
DEMO = ("trace", "stages/downlight.usda", "--target-error", "0.02", "--no-sublayer")
QUICK = ("trace", "stages/reference/isotropic.usda", "--photons", "1000", "--no-sublayer",
         "--no-pictures")

#: The command as the ``lumitrace`` entry point runs it.
RUN = "import sys, lumitrace_launch as L\nsys.exit(L.main())\n"
#: Each start-up mechanism, and the lines that turn it off before the command starts.
MECHANISMS = {
    "kept scenes (a stage run again is not read again)":
        "import lumitrace.stage.scene_cache as s\ns.entry_path = lambda *a, **k: None\n",
    "late loading (USD, thread pools, the other commands' parsers only when used)":
        ("from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, UsdUtils  # noqa\n"
         "import concurrent.futures, logging, multiprocessing, uuid, zipfile  # noqa\n"
         "import OpenEXR  # noqa\n"
         "import lumitrace.cli as c\n"
         "_all = c.build_parser\nc.build_parser = lambda command=None: _all()\n"),
    "layout tables kept on disk, mapped":
        "import lumitrace.table_cache as t\nt._path = lambda fn, args: None\n",
}
#: What the command with each mechanism loads before it starts, as its driver without it
#: does (so that the pair differs by the mechanism alone).
BASELINES = {
    "kept scenes (a stage run again is not read again)":
        "import lumitrace.stage.scene_cache as s\n",
    "late loading (USD, thread pools, the other commands' parsers only when used)": "",
    "layout tables kept on disk, mapped": "import lumitrace.table_cache as t\n",
}
PREAMBLE = "import sys, lumitrace_launch as L\n"


def machine() -> str:
    """The machine the figures were measured on, in words."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    memory = ""
    try:
        kib = int(Path("/proc/meminfo").read_text().split()[1])
        memory = f", {kib / 2 ** 20:.0f} GiB"
    except (OSError, ValueError, IndexError):
        pass
    return (f"{cpu}, {os.cpu_count()} cores{memory}, {platform.system()} "
            f"{platform.release().split('-')[0]}, Python {platform.python_version()}")


def whole_process(argv: list[str], cwd: Path) -> tuple[float, float, float]:
    """Wall s, CPU s (user + system, its waited-for children included) and peak memory
    (MiB, the largest process) of one run of ``argv``."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise RuntimeError(f"{' '.join(argv)} exited {proc.returncode}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def _driver(code: str, out: Path, command=DEMO) -> list[str]:
    return [sys.executable, "-c", PREAMBLE + code + "sys.exit(L.main())\n", *command,
            "--out", str(out)]


def paired(a: list[str], b: list[str], pairs: int, cwd: Path, warm: bool = True) -> dict:
    """A and B in turn, after one warm-up each: the median of the pairs' ratios A / B."""
    if warm:
        whole_process(a, cwd), whole_process(b, cwd)
    runs = [(whole_process(a, cwd), whole_process(b, cwd)) for _ in range(pairs)]
    return {"cpu": statistics.median(ra[1] / rb[1] for ra, rb in runs),
            "wall": statistics.median(ra[0] / rb[0] for ra, rb in runs),
            "b_cpu": statistics.median(rb[1] for _, rb in runs),
            "b_wall": statistics.median(rb[0] for _, rb in runs),
            "b_peak": statistics.median(rb[2] for _, rb in runs)}


def measure(pairs: int, bench_seconds: float, command=DEMO, photons: float = 4e6,
            warm: bool = True) -> list[list[str]]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        shutil.copytree(ROOT / "stages", work / "stages")
        lumitrace = [sys.executable, "-c", RUN]
        demo = [*lumitrace, *command, "--out", str(work / "results")]
        if warm:
            whole_process(demo, work)
        runs = [whole_process(demo, work) for _ in range(pairs)]
        wall, cpu, peak = (statistics.median(r[i] for r in runs) for i in range(3))
        rows.append(["the README's demo command, its stage read before (median of "
                     f"{pairs})", f"{wall:.2f} s wall, {cpu:.2f} s CPU, {peak:.0f} MiB"])
        for name, off in MECHANISMS.items():
            r = paired(_driver(off, work / "off", command),
                       _driver(BASELINES[name], work / "on", command), pairs, work, warm)
            rows.append([f"saved by {name}: the demo command without it over with it "
                         f"({pairs} pairs in turn)",
                         f"CPU {r['cpu']:.3f} (saves {r['cpu'] - 1:.1%} of the command's CPU),"
                         f" wall {r['wall']:.3f}"])
        bench = subprocess.run([*lumitrace, "bench", "--json", "--seconds",
                                str(bench_seconds)], cwd=work, capture_output=True,
                               text=True, check=True)
        b = json.loads(bench.stdout.strip().splitlines()[-1])
        rows.append([f"`lumitrace bench` ({bench_seconds:g} s, {b['threads']} "
                     f"{b['workers']}): the tracer's path segments per second over bare "
                     "Embree's rays per second on the same rays",
                     f"{b['ratio']:.2f} ({b['segments_per_second'] / 1e6:.1f}M against "
                     f"{b['raw_rays_per_second'] / 1e6:.1f}M)"])
        iso = [*lumitrace, "trace", "stages/reference/isotropic.usda", "--photons", f"{photons:g}",
               "--no-pictures", "--no-sublayer", "--quiet", "--out", str(work / "iso")]
        if warm:
            whole_process(iso, work)
        wall, cpu, _ = whole_process(iso, work)
        rows.append([f"the isotropic source, {photons / 1e6:g}M photons, no pictures: photons "
                     "per CPU second of the whole command",
                     f"{photons / cpu / 1e6:.2f}M ({cpu:.2f} s CPU, {wall:.2f} s wall)"])
    return rows


def page_text(rows: list[list[str]], pairs: int, load: float) -> str:
    when = datetime.date.today().isoformat()
    lines = [f"Measured by `python tools/performance_page.py --pairs {pairs}` on {when}, on "
             f"{machine()}, the load average {load:.1f} as it started. Ratios are comparable "
             "within one run only: the same machine drifts from one hour to the next.\n",
             "| figure | value |", "| --- | --- |"]
    lines += [f"| {a} | {b} |" for a, b in rows]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=15)
    ap.add_argument("--bench-seconds", type=float, default=5.0)
    ap.add_argument("--page", type=Path, default=PAGE)
    ap.add_argument("--dry-run", action="store_true", help="print the table, write nothing")
    ap.add_argument("--quick", action="store_true", help="every step in seconds: a check that "
                                                         "the tool runs (implies --dry-run)")
    args = ap.parse_args(argv)
    load = os.getloadavg()[0]
    if args.quick:
        args.dry_run = True
        rows = measure(1, 0.2, QUICK, 1e5, warm=False)
    else:
        rows = measure(args.pairs, args.bench_seconds)
    text = page_text(rows, args.pairs, load)
    print(text)
    if not args.dry_run:
        page = args.page.read_text()
        head, _, rest = page.partition(START)
        _, _, tail = rest.partition(END)
        args.page.write_text(f"{head}{START}\n{text}{END}{tail}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
