"""Throughput benchmark: tracer path segments per second against bare Embree on the same rays.

The tracer runs for a while recording every ray it casts; then the very same rays are cast
again through embreex ``run()`` alone, on the same number of threads, in the same process.
The ratio says how much of the machine's raw intersection rate the photon tracer keeps.
"""
from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from .schema import SCHEMA_DIR
from .tracer import prepare, trace_batch

DEMO_STAGE = SCHEMA_DIR.parent / "stages" / "downlight.usda"


def run_benchmark(stage: str | os.PathLike | None = None, seconds: float = 10.0,
                  threads: int | None = None, resolution: int = 64,
                  batch_size: int = 1 << 17) -> dict:
    """Trace ``stage`` for about ``seconds``, replay its rays through bare Embree; rates."""
    from .stage.reader import read_stage

    path = Path(stage) if stage is not None else DEMO_STAGE
    scene = read_stage(path)
    ps = prepare(scene)
    threads = threads or os.cpu_count() or 1
    flux = [e.flux for e in scene.emitters]
    emitter = max(range(len(flux)), key=flux.__getitem__)

    tallies = []
    start = 0
    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=threads) as pool:
        while time.perf_counter() - t0 < seconds:
            jobs = [(start + k * batch_size) for k in range(threads)]
            start += threads * batch_size
            tallies += list(pool.map(
                lambda s: trace_batch(ps, emitter, 0, s, batch_size, resolution, record_rays=True),
                jobs))
    t_trace = time.perf_counter() - t0
    segments = sum(t.segments for t in tallies)
    photons = sum(t.photons for t in tallies)
    # the same rays, one wavefront at a time, as the tracer cast them
    waves = [ray for t in tallies for ray in t.rays]
    t1 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for _ in pool.map(lambda od: ps.intersect(od[0], od[1]), waves):
            pass
    t_raw = time.perf_counter() - t1
    rays = sum(o.shape[0] for o, _ in waves)
    assert rays == segments
    seg_rate = segments / t_trace
    raw_rate = rays / t_raw
    return {"stage": str(path), "triangles": ps.triangle_count, "threads": threads,
            "photons": photons, "segments": segments, "trace_seconds": t_trace,
            "raw_seconds": t_raw, "photons_per_second": photons / t_trace,
            "segments_per_second": seg_rate, "raw_rays_per_second": raw_rate,
            "ratio": seg_rate / raw_rate}
