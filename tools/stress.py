#!/usr/bin/env python
"""The long part of the stress suite (issue #5): every case of ``tools/stress_cases.py``
with many more photons, bad input through the command line, and a time-bounded fuzz of the
stage reader; prints a table of cases and measured outcomes.

Usage::

    python tools/stress.py                      # about 10 minutes on 2 cores
    python tools/stress.py --photons 2e5 --fuzz-seconds 30     # a few minutes
    python tools/stress.py --only furnace,mirror --markdown    # some cases, as Markdown

The exit status is 1 when a case fails. ``pytest tests/test_stress.py`` runs the same cases
with few photons in CI. Bad requests to the service and malformed scene deltas are tested
with the service (``tests/serve/test_serve.py``).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
try:
    import lumitrace  # noqa: F401
except ImportError:  # running from a source checkout without installing the package
    sys.path.insert(0, str(ROOT / "service"))

import stress_cases as sc  # noqa: E402

#: (case, share of --photons it traces, extra keyword arguments).
TRACED = [
    (sc.case_units, 1.0, {}),
    (sc.case_scales, 1.0, {}),
    (sc.case_far_offset, 1.0, {}),
    (sc.case_die_in_2m_luminaire, 1.0, {}),
    (sc.case_edge_aimed, 5.0, {}),
    (sc.case_white_closed_box, 0.25, {"max_depth": sc.MAX_DEPTH}),
    (sc.case_coincident_faces, 1.0, {}),
    (sc.case_overlapping_faces, 1.0, {}),
    (sc.case_sliver_triangles, 1.0, {}),
    (sc.case_open_bowl, 1.0, {}),
    (sc.case_sheet_both_sides, 1.0, {}),
    (sc.case_flipped_normals, 1.0, {}),
    (sc.case_grazing_mirror, 1.0, {}),
    (sc.case_source_touching_reflector, 10.0, {}),
    (sc.case_facing_mirrors, 0.25, {"n": 300}),
    (sc.case_tir_cube, 0.5, {}),
    (sc.case_accumulator_at_scale, 1.0, {}),
    (sc.case_exr_dynamic_range, 1.0, {}),
    (sc.case_photon_index_beyond_2_32, 0.1, {}),
    (sc.case_white_furnace, 1.0, {}),
    (sc.case_furnace_reflectance, 1.0, {}),
]


def fuzz(kind: str, seconds: float, folder: Path) -> sc.CaseResult:
    """Run one of the reader fuzzers in rounds of 100 examples until ``seconds`` pass."""
    import itertools

    from hypothesis import HealthCheck, given, settings
    from pxr import Usd

    base = sc.fuzz_base_text(folder)
    outcomes: dict[str, int] = {}
    failures: list[str] = []
    numbers = itertools.count()
    strategy = sc.mutations() if kind == "text" else sc.stage_values()

    @settings(max_examples=100, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(strategy)
    def one(x):
        path = folder / f"fuzz{next(numbers)}.usda"
        with sc.quiet_usd():
            if kind == "text":
                path.write_bytes(sc.mutate(base, x))
            else:
                path.write_text(base)
                stage = Usd.Stage.Open(str(path))
                sc.apply_values(stage, x)
                stage.GetRootLayer().Save()
                del stage
            try:
                outcome = sc.read_or_refuse(path)
            except Exception:
                import traceback

                failures.append(f"{x!r}\n{traceback.format_exc()}")
                raise
        path.unlink()
        outcomes[outcome] = outcomes.get(outcome, 0) + 1

    t0 = time.perf_counter()
    failure = ""
    while time.perf_counter() - t0 < seconds:
        try:
            one()
        except Exception as exc:  # noqa: BLE001 - a falsifying example: report it
            failure = f"{type(exc).__name__}: {exc}"[:400]
            print(f"fuzz {kind}: first failing example and its traceback:\n"
                  f"{failures[0] if failures else failure}", file=sys.stderr)
            break
    n = sum(outcomes.values())
    name = "fuzz: mutated stage text" if kind == "text" else "fuzz: attribute values"
    return sc.CaseResult(name, not failure,
                         f"{n} examples in {time.perf_counter() - t0:.0f} s: "
                         f"{outcomes.get('scene', 0)} sound scenes, {outcomes.get('StageError', 0)} "
                         f"StageErrors" + (f"; FAILED on {failure}" if failure else ", nothing else"),
                         "a sound scene or one StageError, never another exception",
                         0, time.perf_counter() - t0)


def table(results: list[sc.CaseResult], markdown: bool) -> str:
    if markdown:
        rows = ["| case | outcome | measured | expected | photons | s |",
                "| --- | --- | --- | --- | ---: | ---: |"]
        for r in results:
            rows.append(f"| {r.name} | {'ok' if r.ok else '**FAILED**'} | {r.measured} | "
                        f"{r.expected} | {r.photons:,} | {r.seconds:.1f} |")
        return "\n".join(rows)
    rows = []
    for r in results:
        rows.append(f"{'ok    ' if r.ok else 'FAILED'} {r.name:38s} {r.photons:>13,} ph "
                    f"{r.seconds:7.1f} s\n       measured: {r.measured}\n       expected: "
                    f"{r.expected}")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--photons", type=float, default=1e6, help="photons per case (default 1e6)")
    p.add_argument("--fuzz-seconds", type=float, default=120.0,
                   help="seconds for each of the two fuzzers (default 120)")
    p.add_argument("--only", default="", help="comma-separated parts of case names to run")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    args = p.parse_args(argv)
    wanted = [w.strip().lower() for w in args.only.split(",") if w.strip()]

    def chosen(name: str) -> bool:
        return not wanted or any(w in name.lower() for w in wanted)

    results = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for i, (case, share, kwargs) in enumerate(TRACED):
            if not chosen(case.__name__):
                continue
            sub = folder / f"case{i}"
            sub.mkdir()
            result = case(sub, max(int(args.photons * share), 1000), **kwargs)
            results.append(result)
            print(("ok     " if result.ok else "FAILED ") + result.name, file=sys.stderr)
        for i, (name, make, needles) in enumerate(sc.BAD_INPUTS):
            if chosen("bad input " + name):
                results.append(sc.bad_input_case(name, make, needles, folder / f"bad{i}"))
        if chosen("results survive bad input"):
            sub = folder / "kept"
            sub.mkdir()
            results.append(sc.case_results_survive_bad_input(sub, 0))
        for kind in ("text", "values"):
            if chosen(f"fuzz {kind}") and args.fuzz_seconds > 0:
                sub = folder / f"fuzz_{kind}"
                sub.mkdir()
                results.append(fuzz(kind, args.fuzz_seconds, sub))
                print(("ok     " if results[-1].ok else "FAILED ") + results[-1].name,
                      file=sys.stderr)
    print(table(results, args.markdown))
    failed = [r.name for r in results if not r.ok]
    print(f"\n{len(results) - len(failed)} of {len(results)} cases ok" +
          (f"; failed: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
