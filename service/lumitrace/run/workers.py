"""Where photon batches run: a thread pool in this process, or a pool of worker processes.

Batches are pure functions of (scene, emitter, seed, first photon, count), so both give the
same tallies. Threads share one prepared scene and overlap Embree (which releases the GIL)
with numpy; processes each prepare the scene once and run numpy without contending for the
GIL, which pays off on long runs once their start-up (about a second) is amortised.
"""
from __future__ import annotations

import contextlib
import multiprocessing
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from typing import Callable, Iterable, Iterator

from ..film.tally import BatchTally
from ..scene import Scene
from ..trace.job import BatchJob
from ..trace.prepared import PreparedScene, prepare
from ..trace.tracer import trace_batch

#: Photon budgets from which "auto" uses worker processes.
PROCESS_MIN_PHOTONS = 8_000_000

_worker_scene: PreparedScene | None = None


def _init_worker(scene: Scene, frame) -> None:
    global _worker_scene
    _worker_scene = prepare(scene, frame)


def _run_job(job: BatchJob) -> BatchTally:
    return trace_batch(_worker_scene, job)


def choose(mode: str, threads: int, budget: int | None) -> str:
    """"threads" or "processes" for a run of ``budget`` photons (None: time or error)."""
    if mode != "auto":
        return mode
    if threads > 1 and (budget is None or budget >= PROCESS_MIN_PHOTONS):
        return "processes"
    return "threads"


@contextlib.contextmanager
def batch_runner(scene: Scene, ps: PreparedScene, mode: str, threads: int
                 ) -> Iterator[Callable[[Iterable[BatchJob]], Iterator[BatchTally]]]:
    """A function mapping jobs to their tallies, in job order, on ``threads`` workers."""
    if mode == "processes":
        ctx = multiprocessing.get_context("spawn")  # no fork: Embree keeps threads
        with ProcessPoolExecutor(max_workers=threads, mp_context=ctx, initializer=_init_worker,
                                 initargs=(scene, ps.frame)) as pool:
            list(pool.map(_noop, range(threads)))  # start every worker before timing
            yield lambda jobs: pool.map(_run_job, list(jobs))
    elif mode == "threads":
        with ThreadPoolExecutor(max_workers=threads) as pool:
            yield lambda jobs: pool.map(lambda job: trace_batch(ps, job), jobs)
    else:
        raise ValueError(f"workers must be auto, threads or processes, got {mode!r}")


def _noop(_) -> None:
    return None
