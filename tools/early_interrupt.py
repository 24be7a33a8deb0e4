"""SIGINT at chosen delays after a ``lumitrace trace`` process starts, and what came of it.

For each way in (the ``lumitrace`` console entry point, ``python -m lumitrace``), each
disposition of SIGINT the process starts with (``default``: as from a terminal or a
program; ``ignored``: as a background job of a shell script inherits it) and each delay
(ms after the process was started, ``exec`` done), a trace of a small stage whose outputs
already exist gets SIGINT, and the outcome is tabulated:

- ``stopped``: exit 130, lumitrace's one line, the outputs unchanged;
- ``killed``: ended by the signal's default action before Python took it (status -2;
  -15 for ``--signal TERM``), the outputs unchanged;
- ``traceback``: a KeyboardInterrupt in the interpreter's start-up, before lumitrace's
  first line ran (exit 1), the outputs unchanged;
- ``rewritten``: exit 0 and the outputs rewritten: the signal was lost (only where it was
  ignored at the start and arrived before lumitrace's first line set its handler);
- ``other``: anything else (its status is shown).

    python tools/early_interrupt.py --delays 0,5,10,20,40,80 --repeats 5

prints a table per way in and disposition (counts of each outcome per delay) and, with
``--json``, one JSON object. Where ``rewritten`` appears is the window that is left. It
also times, as whole processes (median of ``--repeats``), the interpreter alone
(``python -I -S -c pass``), the interpreter with this environment's site start-up
(``python -c pass``: its ``.pth`` files, an editable install's finder among them) and the
same up to lumitrace's recorders (``python -c "import lumitrace_launch"``): the window
lies inside the last.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STAGE = ROOT / "stages" / "reference" / "isotropic.usda"
OUTCOMES = ("stopped", "killed", "traceback", "rewritten", "other")
STOPPED = "lumitrace: SIGINT: interrupted; nothing was written, earlier outputs are unchanged"


def _launchers() -> dict[str, list[str]]:
    entry = Path(sys.executable).with_name("lumitrace")
    out = {"python -m lumitrace": [sys.executable, "-m", "lumitrace"]}
    if entry.exists():
        out = {"lumitrace": [str(entry)], **out}
    return out


def _digest(folder: Path) -> str:
    h = hashlib.sha256()
    for name in ("iso.ies", "iso.ldt", "iso.lumitrace.usda"):
        h.update((folder / name).read_bytes())
    return h.hexdigest()


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def trial(command: list[str], folder: Path, delay_s: float, ignored: bool,
          sig: int = signal.SIGINT) -> tuple[str, int]:
    """One run sent ``sig`` ``delay_s`` after it started: (outcome, exit status)."""
    before = _digest(folder)
    args = [*command, "trace", str(folder / "iso.usda"), "--photons", "20000",
            "--resolution", "8", "--no-pictures", "--no-progress", "--quiet"]
    p = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                         preexec_fn=_ignore_sigint if ignored else None)
    time.sleep(delay_s)  # counted from here: Popen returns once the child has exec'd
    p.send_signal(sig)
    _, err = p.communicate(timeout=300)
    same = _digest(folder) == before
    lines = err.strip().splitlines()
    name = signal.Signals(sig).name
    if p.returncode == 128 + sig and same and lines[-1:] == [STOPPED.replace("SIGINT", name)]:
        return "stopped", p.returncode
    if p.returncode == -sig and same:
        return "killed", p.returncode
    if p.returncode == 1 and same and "KeyboardInterrupt" in err:
        return "traceback", p.returncode
    if p.returncode == 0 and not same:
        return "rewritten", p.returncode
    return "other", p.returncode


def startup_ms(repeats: int) -> dict[str, float]:
    """Median wall time (ms) of the processes that bound the window (see the module's
    note)."""
    import statistics

    probes = {"interpreter alone": [sys.executable, "-I", "-S", "-c", "pass"],
              "with site start-up": [sys.executable, "-c", "pass"],
              "to lumitrace's recorders": [sys.executable, "-c", "import lumitrace_launch"]}
    out = {}
    for name, command in probes.items():
        times = []
        for _ in range(max(repeats, 3)):
            t0 = time.perf_counter()
            subprocess.run(command, check=True)
            times.append(1000.0 * (time.perf_counter() - t0))
        out[name] = statistics.median(times)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--delays", default="0,5,10,20,40,80,160",
                    help="delays after the start, ms, comma-separated")
    ap.add_argument("--repeats", type=int, default=3, help="runs per delay")
    ap.add_argument("--dispositions", default="default,ignored")
    ap.add_argument("--signal", choices=("INT", "TERM"), default="INT",
                    help="the signal sent (SIGINT by default; SIGTERM to compare)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    delays = [float(d) for d in args.delays.split(",")]
    results = {}
    with tempfile.TemporaryDirectory(prefix="lumitrace-sigint-") as tmp:
        folder = Path(tmp)
        shutil.copy(STAGE, folder / "iso.usda")
        first = subprocess.run([*_launchers()["python -m lumitrace"], "trace",
                                str(folder / "iso.usda"), "--photons", "20000",
                                "--resolution", "8", "--no-pictures", "--quiet"])
        if first.returncode != 0:
            return first.returncode
        for name, command in _launchers().items():
            for disposition in args.dispositions.split(","):
                table = {}
                for d in delays:
                    counts = dict.fromkeys(OUTCOMES, 0)
                    others = []
                    for _ in range(args.repeats):
                        outcome, code = trial(command, folder, d / 1000.0,
                                              disposition == "ignored",
                                              getattr(signal, f"SIG{args.signal}"))
                        counts[outcome] += 1
                        if outcome == "other":
                            others.append(code)
                    table[d] = {**counts, "other_statuses": others}
                results[f"{name}, SIGINT {disposition}, SIG{args.signal} sent"] = table
    startup = startup_ms(args.repeats)
    if args.json:
        print(json.dumps({"delays_ms": delays, "repeats": args.repeats,
                          "results": results, "startup_ms": startup}))
        return 0
    print("process start-up, median ms: " + ", ".join(f"{k} {v:.1f}"
                                                       for k, v in startup.items()))
    for key, table in results.items():
        print(f"\n{key} ({args.repeats} runs per delay)")
        print("| delay (ms) | " + " | ".join(OUTCOMES) + " |")
        print("|---:|" + "---:|" * len(OUTCOMES))
        for d, counts in table.items():
            extra = f" {counts['other_statuses']}" if counts["other_statuses"] else ""
            print(f"| {d:g} | " + " | ".join(str(counts[o]) for o in OUTCOMES) + f" |{extra}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
