"""Throughput benchmark: tracer path segments per second against bare Embree on the same rays.

Every worker traces a batch of photons (timed), traces it again recording each ray it
casts (not timed: keeping the rays is the benchmark's own work), then casts the very same
rays through embreex ``run()`` alone (timed). With all workers busy the
whole time, rates are total segments over the summed times per worker. The ratio says how
much of the machine's raw intersection rate the photon tracer keeps.
"""
from __future__ import annotations

import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

from ..schema import SCHEMA_DIR
from ..trace import compiled
from ..trace.embree import PartScene
from ..trace.job import BatchJob
from ..trace.prepared import PreparedScene, embree_scene, normalised, prepare
from ..trace.tracer import trace_batch

DEMO_STAGE = SCHEMA_DIR.parent / "stages" / "downlight.usda"
_worker_scene: PreparedScene | None = None
_worker_embreex = None


def _init(stage: str) -> None:
    global _worker_scene, _worker_embreex
    import numpy as np

    from ..stage.reader import read_stage

    ps = _worker_scene = prepare(read_stage(stage))
    tri = normalised(ps.scene, ps.center, ps.scale)
    _worker_embreex = embree_scene(np.ascontiguousarray(tri, dtype=np.float32), (),
                                   parts=False)  # the reference: bare embreex


def _job(job: BatchJob) -> tuple[int, int, float, float]:
    """(photons, segments, trace seconds, bare-Embree seconds) of one batch."""
    ps = _worker_scene
    t0 = time.perf_counter()
    tally = trace_batch(ps, job)
    t1 = time.perf_counter()
    rays = trace_batch(ps, job, record_rays=True).rays  # the same rays, kept (not timed)
    t2 = time.perf_counter()
    for o, d in rays:
        _worker_embreex.run(o, d, output=1)
    t3 = time.perf_counter()
    return job.count, tally.segments, t1 - t0, t3 - t2


def run_benchmark(stage: str | os.PathLike | None = None, seconds: float = 10.0,
                  threads: int | None = None, resolution: int = 64,
                  batch_size: int = 1 << 17, workers: str = "processes") -> dict:
    """Trace ``stage`` for about ``seconds`` on ``threads`` workers; rates and their ratio."""
    from ..stage.reader import read_stage

    path = Path(stage) if stage is not None else DEMO_STAGE
    scene = read_stage(path)
    threads = threads or os.cpu_count() or 1
    flux = [e.flux for e in scene.emitters]
    emitter = max(range(len(flux)), key=flux.__getitem__)
    if workers == "processes":
        pool = ProcessPoolExecutor(threads, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_init, initargs=(str(path),))
    else:
        _init(str(path))
        pool = ThreadPoolExecutor(threads)
    results = []
    with pool:
        list(pool.map(_job, [BatchJob(emitter, 0, 1024, 0, resolution)] * threads))  # warm up
        start, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            jobs = [BatchJob(emitter, start + k * batch_size, batch_size, 0, resolution)
                    for k in range(threads)]
            start += threads * batch_size
            results += list(pool.map(_job, jobs))
    photons = sum(r[0] for r in results)
    segments = sum(r[1] for r in results)
    t_trace = sum(r[2] for r in results) / threads
    t_raw = sum(r[3] for r in results) / threads
    ps = prepare(scene)
    return {"stage": str(path), "triangles": ps.triangle_count, "threads": threads,
            "workers": workers, "kernels": compiled.backend(),
            "embree": "parts" if isinstance(ps.embree, PartScene) else "embreex",
            "photons": photons,
            "segments": segments,
            "trace_seconds": t_trace, "raw_seconds": t_raw,
            "photons_per_second": photons / t_trace, "segments_per_second": segments / t_trace,
            "raw_rays_per_second": segments / t_raw, "ratio": t_raw / t_trace}


def summary_text(report: dict) -> str:
    """The benchmark's report as the command prints it, one figure a line."""
    kernels = "built ahead of time" if report["kernels"] == "aot" else "numba's JIT"
    embree = ("through its C API, a geometry per part" if report["embree"] == "parts"
              else "through embreex")
    return "\n".join([
        f"stage                {report['stage']}",
        f"triangles            {report['triangles']:,}",
        f"photons              {report['photons']:,}",
        f"workers              {report['threads']} {report['workers']}",
        f"kernels              {kernels}, Embree {embree}",
        f"tracer               {report['segments_per_second']:,.0f} segments/s "
        f"({report['photons_per_second']:,.0f} photons/s)",
        f"bare embreex run()   {report['raw_rays_per_second']:,.0f} rays/s on the same rays",
        f"ratio                {report['ratio']:.2f}"])
