"""Where a run's time goes, phase by phase, in CPU seconds of the threads that did the work.

    python tools/profile_run.py [--stage stages/downlight.usda] [--photons 2000000] [--json]

Each phase is timed by wrapping the functions that do it (thread CPU time, so the tracing
threads are counted too): importing, stage reading, scene preparation, then per batch
emission, the photon paths and the Python around them, then the map estimates (pull-push
and its error), the photometry, the outputs (files, pictures). A path's Embree hits are
taken inside the compiled bounce kernel (scattering, offsets, binning into cube-map
texels, goniophotometer cells and exits), so the split between the two is Embree's share
of one batch's time, measured on its rays cast alone: a lower bound, since alone its
tree stays in the caches that the paths share with their own tables (on the mirror cup,
10M photons: 53% here, 70% of the paths' samples in a sampling profiler of the whole
command). The stage is traced from a copy, so the repository is left as it was.
"""
from __future__ import annotations

import argparse
import functools
import json
import shutil
import sys
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path

T0 = time.perf_counter()
C0 = time.process_time()
import lumitrace  # noqa: E402,F401  (the import is the first phase)

IMPORT = (time.perf_counter() - T0, time.process_time() - C0)

ROOT = Path(__file__).resolve().parents[1]
_cpu: dict[str, float] = defaultdict(float)
_calls: dict[str, int] = defaultdict(int)
_lock = threading.Lock()
_local = threading.local()


def _timed(phase: str, fn):
    """``fn`` counting its thread CPU time under ``phase``, minus nested timed calls."""
    @functools.wraps(fn)
    def wrapper(*a, **k):
        stack = getattr(_local, "stack", None)
        if stack is None:
            stack = _local.stack = []
        t = time.thread_time()
        stack.append(0.0)
        try:
            return fn(*a, **k)
        finally:
            inner = stack.pop()
            spent = time.thread_time() - t
            if stack:
                stack[-1] += spent
            with _lock:
                _cpu[phase] += spent - inner
                _calls[phase] += 1
    return wrapper


def _patch():
    from lumitrace.photometry import distribution
    from lumitrace.publish import outputs, photometric
    from lumitrace.run import session, workers
    from lumitrace.trace import compiled, prepared, tracer

    workers.trace_batch = _timed("tracer (Python around the kernels)", tracer.trace_batch)
    tracer.emit = _timed("emission", tracer.emit)
    compiled.start = _timed("emission", compiled.start)
    compiled.bounce = _timed(PATHS, compiled.bounce)
    tracer.counts_of = _timed(PATHS, tracer.counts_of)
    prepared.PreparedScene.intersect = _timed(PATHS, prepared.PreparedScene.intersect)
    session.estimate = _timed("map estimates (filter, errors)", session.estimate)
    outputs.photometry_of = _timed("photometry", distribution.photometry_of)
    photometric.polar_diagram = _timed("pictures", photometric.polar_diagram)
    photometric.photometric_solid = _timed("pictures", photometric.photometric_solid)


def profile(stage: Path, photons: int) -> dict:
    _patch()
    from lumitrace.publish.outputs import write_outputs
    from lumitrace.run.session import TraceSettings, run
    from lumitrace.stage.reader import read_stage
    from lumitrace.trace import prepared

    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / stage.name
        shutil.copy(stage, copy)
        wall = {}
        t = time.perf_counter()
        c = time.process_time()
        scene = read_stage(copy)
        _cpu["stage reading"] += time.process_time() - c
        t1 = time.perf_counter()
        c = time.process_time()
        ps = prepared.prepare(scene)
        _cpu["scene preparation"] += time.process_time() - c
        t2 = time.perf_counter()
        result = run(scene, TraceSettings(photons=photons, workers="threads"), prepared=ps)
        t3 = time.perf_counter()
        c = time.thread_time()
        write_outputs(result, None)
        _cpu["outputs (files)"] += time.thread_time() - c
        t4 = time.perf_counter()
        wall = {"import": IMPORT[0], "read": t1 - t, "prepare": t2 - t1, "trace": t3 - t2,
                "outputs": t4 - t3}
    _split_paths(ps)
    # outputs include photometry and pictures, timed on their own: take them out
    _cpu["outputs (files)"] -= _cpu["photometry"] + _cpu["pictures"]
    cpu = {"import": IMPORT[1], **_cpu}
    return {"stage": str(stage), "photons": photons, "wall_seconds": wall,
            "cpu_seconds": dict(sorted(cpu.items(), key=lambda kv: -kv[1])),
            "calls": dict(_calls),
            "photons_per_cpu_second_tracing": photons / max(
                sum(v for k, v in _cpu.items() if k in TRACING), 1e-9)}


PATHS = "photon paths"
EMBREE = "intersection (Embree)"
BOUNCES = "bounce kernel (scattering, binning)"
TRACING = ("tracer (Python around the kernels)", "emission", BOUNCES, EMBREE)


def _split_paths(ps) -> None:
    """Split the paths' time into Embree's and the compiled bounces': Embree is called
    from inside the compiled paths, so its share is measured on one batch, whose rays
    (kept by tracing it a bounce at a time) are cast again through Embree alone."""
    from lumitrace.trace.job import BatchJob
    from lumitrace.trace.tracer import trace_batch

    spent = _cpu[PATHS]
    share = 0.0
    if ps.embree is not None:
        job = BatchJob(0, 1 << 30, 1 << 16, 0, 64)
        trace_batch(ps, job)
        t = time.thread_time()
        trace_batch(ps, job)
        deep = time.thread_time() - t
        rays = trace_batch(ps, job, record_rays=True).rays
        t = time.thread_time()
        for o, d in rays:
            ps.intersect(o, d)
        share = min((time.thread_time() - t) / deep, 1.0)
    del _cpu[PATHS]  # (with this measurement's own)
    _cpu[EMBREE] += share * spent
    _cpu[BOUNCES] += (1.0 - share) * spent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stage", type=Path, default=ROOT / "stages" / "downlight.usda")
    ap.add_argument("--photons", type=int, default=2_000_000)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    import warnings

    warnings.simplefilter("ignore")
    r = profile(args.stage, args.photons)
    if args.json:
        print(json.dumps(r, indent=1))
        return 0
    total = sum(r["cpu_seconds"].values())
    print(f"{r['stage']}, {r['photons']:,} photons: {total:.2f} CPU s in all; wall "
          + ", ".join(f"{k} {v:.2f} s" for k, v in r["wall_seconds"].items()))
    for k, v in r["cpu_seconds"].items():
        print(f"  {k:32s} {v:7.2f} CPU s  {v / total:6.1%}")
    print(f"  tracing: {r['photons_per_cpu_second_tracing']:,.0f} photons per CPU second")
    print(f"  ({EMBREE}: its rays cast again alone, a lower bound of its share in the paths)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
