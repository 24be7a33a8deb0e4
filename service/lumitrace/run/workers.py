"""Where photon batches run: a thread pool in this process, or a pool of worker processes.

Batches are pure functions of (scene, emitter, seed, first photon, count), so both give the
same tallies. Threads share one prepared scene; Embree and the compiled photon kernels both
release the GIL, so threads keep every core busy and are the default. Worker processes
each import lumitrace and prepare the scene again (about a second each) and remain for
those who ask for them (measured on 10M photons of the demo on 2 cores: threads 13.9 s
and 22.3 CPU s, processes 16.0 s and 25.2 CPU s).
"""
from __future__ import annotations

import contextlib
import ctypes
import signal
import sys
from typing import TYPE_CHECKING, Callable, Iterable, Iterator

from ..film.accumulate import compact
from ..film.tally import BatchTally
from ..scene import Scene
from ..trace.job import BatchJob
from ..trace.prepared import PreparedScene, prepare
from ..trace.tracer import trace_batch

if TYPE_CHECKING:
    from concurrent.futures import ProcessPoolExecutor

_worker_scene: PreparedScene | None = None


def _init_worker(scene: Scene, frame) -> None:
    global _worker_scene
    _detach_from_signals()
    _worker_scene = prepare(scene, frame)


def _detach_from_signals() -> None:
    """A worker leaves SIGINT and SIGHUP to its parent (which ends the pool) and, on Linux,
    is sent SIGTERM when the parent dies, so no worker outlives a killed run."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass


def _end_pool(pool: ProcessPoolExecutor) -> None:
    """Stop a process pool now: queued jobs cancelled, running workers terminated."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(timeout=5)


def _traced(ps: PreparedScene, job: BatchJob) -> BatchTally:
    """The job's tally, its counts compacted: a batch of a few photons in a big map keeps
    only the texels it hit while it waits to be added (many emitters: many small jobs)."""
    tally = trace_batch(ps, job)
    tally.counts = compact(tally.counts, tally.photons)
    tally.cells = compact(tally.cells, tally.photons)
    return tally


def _run_job(job: BatchJob) -> BatchTally:
    return _traced(_worker_scene, job)


def choose(mode: str, threads: int, budget: int | None) -> str:
    """"threads" or "processes" for a run of ``budget`` photons (None: time or error):
    threads unless processes are asked for."""
    return "threads" if mode == "auto" else mode


@contextlib.contextmanager
def batch_runner(scene: Scene, ps: PreparedScene, mode: str, threads: int,
                 scheduler: str | None = None
                 ) -> Iterator[Callable[[Iterable[BatchJob]], Iterator[BatchTally]]]:
    """A function mapping jobs to their tallies, in job order, on ``threads`` workers (or
    mode "dask": on the workers of the Dask ``scheduler``, see :mod:`.cluster`)."""
    if mode == "dask":
        from .cluster import cluster_runner

        runner = cluster_runner(scheduler, scene, ps.frame)
        try:
            yield runner
        finally:
            runner.close()
    elif mode == "processes":  # (multiprocessing loaded only here: 15 ms at every start)
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        ctx = multiprocessing.get_context("spawn")  # no fork: Embree keeps threads
        pool = ProcessPoolExecutor(max_workers=threads, mp_context=ctx,
                                   initializer=_init_worker, initargs=(scene, ps.frame))
        try:
            list(pool.map(_noop, range(threads)))  # start every worker before timing
            yield lambda jobs: pool.map(_run_job, list(jobs))
        except BaseException:
            _end_pool(pool)
            raise
        pool.shutdown(wait=True)
    elif mode == "threads":
        pool = _ThreadPool(ps, threads)
        try:
            yield pool.map
        finally:
            pool.shutdown()
    else:
        raise ValueError(f"workers must be auto, threads or processes, got {mode!r}")


def _noop(_) -> None:
    return None


class _ThreadPool:
    """Jobs traced on ``threads`` threads of this process, in job order. A round of one
    job is traced in the calling thread (a pool's threads could only wait for it), and
    the pool, with concurrent.futures (8 ms to load), is made for the first round of
    more: a small run never loads it."""

    def __init__(self, ps: PreparedScene, threads: int):
        self.ps, self.threads, self.pool = ps, threads, None

    def map(self, jobs: Iterable[BatchJob]) -> Iterator[BatchTally]:
        jobs = list(jobs)
        if len(jobs) == 1:
            return iter([_traced(self.ps, jobs[0])])
        if self.pool is None:
            from concurrent.futures.thread import ThreadPoolExecutor

            self.pool = ThreadPoolExecutor(max_workers=self.threads)
        return self.pool.map(lambda job: _traced(self.ps, job), jobs)

    def shutdown(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=True)
