"""Photon batches on Dask against the local thread pool, and what a cluster could keep busy.

    python tools/dask_bench.py [--photons 4000000] [--resolution 64] [--batch-size 131072]
                               [--small-batches 200] [--json]

In one run, on the demo stage: the tracing throughput (photons/s, tracing time of the
session, the scene's preparation excluded) of the local thread pool on every core, and of
a loopback ``distributed.LocalCluster`` with 1 and 2 single-threaded worker processes
(their counts checked equal to the local run's); the overhead per batch (a run of many
tiny batches on one worker, less the same batches traced here in one thread); the
size of one compacted tally as sent (and as pickled) and the client's time to unpack
and add it. From these, on
paper: the workers a 1e9-photon run can keep busy over a 1 Gbit/s link before the
client (its link, its summing, or the per-batch overhead) becomes the limit.
"""
from __future__ import annotations

import argparse
import json
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "service"))

from lumitrace.film.accumulate import Accumulator  # noqa: E402
from lumitrace.run.cluster import cluster_runner, pack, unpack  # noqa: E402
from lumitrace.run.session import run  # noqa: E402
from lumitrace.run.settings import TraceSettings  # noqa: E402
from lumitrace.run.workers import _traced  # noqa: E402
from lumitrace.stage.reader import read_stage  # noqa: E402
from lumitrace.trace.job import BatchJob  # noqa: E402
from lumitrace.trace.prepared import prepare  # noqa: E402

LINK_BYTES_PER_S = 1e9 / 8
TARGET_PHOTONS = 1e9


def _cluster(n: int):
    from distributed import LocalCluster

    return LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                        dashboard_address=":0")


def _throughput(scene, settings) -> tuple[float, object]:
    r = run(scene, settings)
    return r.photons / r.seconds, r


def _same(a, b) -> bool:
    return all(np.array_equal(x.counts, y.counts) and x.absorbed == y.absorbed
               for x, y in zip(a.accumulator.emitters, b.accumulator.emitters))


def _overhead(scene, address: str, n: int, photons: int, resolution: int) -> float:
    """Seconds a batch costs on the cluster beyond its tracing: ``n`` batches of
    ``photons`` on one worker, less the same batches traced here in one thread."""
    ps = prepare(scene)
    jobs = [BatchJob(0, i * photons, photons, 0, resolution) for i in range(n)]
    _traced(ps, jobs[0])
    t0 = time.perf_counter()
    for j in jobs:
        _traced(ps, j)
    local = time.perf_counter() - t0
    runner = cluster_runner(address, scene, ps.frame)
    try:
        list(runner(jobs[:4]))  # the scene there, prepared, before timing
        t0 = time.perf_counter()
        list(runner(jobs))
        remote = time.perf_counter() - t0
    finally:
        runner.close()
    return max(0.0, remote - local) / n


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=float, default=4e6)
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--batch-size", type=int, default=1 << 17)
    ap.add_argument("--small-batches", type=int, default=200,
                    help="tiny batches (64 photons) timed for the overhead per batch")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    scene = read_stage(ROOT / "stages" / "downlight.usda")
    base = dict(photons=int(args.photons), resolution=args.resolution,
                batch_size=args.batch_size, seed=1)
    cores = os.cpu_count() or 1
    out: dict = {"stage": "downlight.usda", "photons": int(args.photons), "cores": cores,
                 "batch_size": args.batch_size, "resolution": args.resolution}
    _throughput(scene, TraceSettings(photons=50_000, resolution=args.resolution))  # warm up
    rate, local = _throughput(scene, TraceSettings(threads=cores, **base))
    out["local_threads_photons_per_s"] = rate
    for n in (1, 2):
        with _cluster(n) as c:
            _throughput(scene, TraceSettings(photons=50_000, resolution=args.resolution,
                                             scheduler=c.scheduler_address))  # warm up
            rate, remote = _throughput(scene, TraceSettings(scheduler=c.scheduler_address,
                                                            threads=n, **base))
            out[f"dask_{n}_workers_photons_per_s"] = rate
            out[f"dask_{n}_workers_identical"] = _same(local, remote)
            if n == 1:
                out["overhead_per_batch_s"] = _overhead(scene, c.scheduler_address,
                                                        args.small_batches, 64,
                                                        args.resolution)
    ps = prepare(scene)
    tally = _traced(ps, BatchJob(0, 0, args.batch_size, 1, args.resolution))
    wire = pack(tally)
    acc = Accumulator(scene, args.resolution, ps.goniometer)
    acc.add(unpack(wire))
    t0 = time.perf_counter()
    reps = 20
    for _ in range(reps):  # the same tally again: the same work as the next batch's
        acc.add(unpack(wire))
    add_s = (time.perf_counter() - t0) / reps
    out.update(tally_bytes=len(wire), tally_pickled_bytes=len(pickle.dumps(tally, protocol=5)),
               client_add_s=add_s)
    out["paper"] = paper(out, args.batch_size)
    if args.json:
        print(json.dumps(out))
    else:
        print(text(out))
    return 0


def paper(m: dict, batch: int) -> dict:
    """How many workers a 1e9-photon run keeps busy: each worker makes ``rate / batch``
    tallies a second; the client takes at most one per max(transfer, add, overhead)."""
    per_worker = m["dask_1_workers_photons_per_s"]
    per_tally_s = {"link": m["tally_bytes"] / LINK_BYTES_PER_S, "summing": m["client_add_s"],
                   "overhead": m["overhead_per_batch_s"]}
    limit = max(per_tally_s, key=per_tally_s.get)
    tallies_per_s = 1.0 / max(per_tally_s[limit], 1e-9)
    workers = tallies_per_s * batch / per_worker
    photons_per_s = workers * per_worker
    return {"per_tally_s": per_tally_s, "limit": limit, "workers": workers,
            "photons_per_s": photons_per_s, "batches": TARGET_PHOTONS / batch,
            "seconds_1e9": TARGET_PHOTONS / photons_per_s,
            "link_bytes_1e9": TARGET_PHOTONS / batch * m["tally_bytes"]}


def text(m: dict) -> str:
    p = m["paper"]
    return "\n".join([
        f"demo stage, {m['photons']:,} photons, batch {m['batch_size']:,}, resolution "
        f"{m['resolution']}, {m['cores']} cores",
        f"local thread pool ({m['cores']} threads)  {m['local_threads_photons_per_s']:,.0f} "
        "photons/s",
        f"dask, 1 worker process        {m['dask_1_workers_photons_per_s']:,.0f} photons/s "
        f"(counts identical: {m['dask_1_workers_identical']})",
        f"dask, 2 worker processes      {m['dask_2_workers_photons_per_s']:,.0f} photons/s "
        f"(counts identical: {m['dask_2_workers_identical']})",
        f"overhead per batch            {m['overhead_per_batch_s'] * 1e3:.2f} ms",
        f"tally of one batch            {m['tally_bytes'] / 1e3:.1f} kB on the wire "
        f"({m['tally_pickled_bytes'] / 1e3:.1f} kB pickled), {m['client_add_s'] * 1e3:.2f} ms "
        "to unpack and add",
        f"1e9 photons on 1 Gbit/s       {p['batches']:,.0f} batches, "
        f"{p['link_bytes_1e9'] / 1e9:.2f} GB of tallies; per tally: link "
        f"{p['per_tally_s']['link'] * 1e3:.2f} ms, summing "
        f"{p['per_tally_s']['summing'] * 1e3:.2f} ms, overhead "
        f"{p['per_tally_s']['overhead'] * 1e3:.2f} ms",
        f"  -> about {p['workers']:,.0f} workers like these before the {p['limit']} limits; "
        f"1e9 photons in {p['seconds_1e9']:,.0f} s"])


if __name__ == "__main__":
    sys.exit(main())
