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
import threading
import time
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
            yield pool
        finally:
            pool.shutdown()
    else:
        raise ValueError(f"workers must be auto, threads or processes, got {mode!r}")


def _noop(_) -> None:
    return None


#: The pool is started once the photons still to trace (the run's, where it knows them,
#: else the round's) would take one thread at least this long (s): a second thread would
#: save at most half of it in wall time and costs CPU time to start (concurrent.futures'
#: import, the thread, its buffers' first pages). On the mirror cup to 2%, a last round of
#: 65,536 photons (30 ms) split took 1.05 of the CPU time and no less wall time.
START_POOL_SECONDS = 0.05
#: A round one thread traces in less than this (s) is one job traced here alone: a split
#: round costs one more batch's fixed work (its set-up, its tallies' arrays and adds).
INLINE_SECONDS = 0.01


class _ThreadPool:
    """Jobs traced on ``threads`` threads of this process (the calling one among them), in
    job order. :meth:`ways` tells the session how to split a round: in one job, traced in
    the calling thread alone, while one thread traces it in less than
    :data:`INLINE_SECONDS` or while the run's work left is too little to start the pool
    for (:data:`START_POOL_SECONDS`), at the rate of the batches so far; else among the
    threads. Before any rate is known a round's first job is traced alone to measure it.
    The tallies are the same for any split."""

    def __init__(self, ps: PreparedScene, threads: int):
        self.ps, self.threads, self.pool = ps, threads, None
        self.seconds_per_photon: float | None = None  # on one thread, the last measured

    def ways(self, photons: int, remaining: float | None = None) -> int:
        """How many ways to split a round of ``photons``, the run having about
        ``remaining`` photons still to trace (None: unknown)."""
        return self.threads if self._shared(photons, remaining) else 1

    def _shared(self, photons: int, remaining: float | None = None) -> bool:
        rate = self.seconds_per_photon
        if self.threads == 1 or rate is None:
            return self.threads > 1
        if self.pool is None and rate * max(photons, remaining or 0) < START_POOL_SECONDS:
            return False
        return rate * photons >= INLINE_SECONDS

    def _timed(self, job: BatchJob) -> BatchTally:
        t0 = time.perf_counter()
        tally = _traced(self.ps, job)
        self.seconds_per_photon = (time.perf_counter() - t0) / max(job.count, 1)
        return tally

    def __call__(self, jobs: Iterable[BatchJob]) -> Iterator[BatchTally]:
        """The jobs' tallies, traced as they are asked for (a caller's clock around the
        iteration times the round)."""
        jobs = list(jobs)
        alone = len(jobs) <= 1 or self.threads == 1
        if self.seconds_per_photon is None and not alone:
            yield self._timed(jobs.pop(0))  # a first round: its first job gives the rate
            alone = len(jobs) <= 1 or not self._shared(sum(j.count for j in jobs))
        if alone:
            for job in jobs:
                yield self._timed(job)
            return
        t0 = time.perf_counter()
        tallies = self._together(jobs)
        self.seconds_per_photon = (time.perf_counter() - t0) * min(self.threads, len(jobs)) \
            / max(sum(j.count for j in jobs), 1)
        yield from tallies

    def _together(self, jobs: list[BatchJob]) -> list[BatchTally]:
        """The jobs traced by this thread and the pool's, each taking the next job left:
        this thread's wave buffers are already warm, and the pool needs one thread less."""
        if self.pool is None:
            from concurrent.futures.thread import ThreadPoolExecutor

            self.pool = ThreadPoolExecutor(max_workers=self.threads - 1)
        tallies: list[BatchTally | None] = [None] * len(jobs)
        left = iter(enumerate(jobs))
        lock, stop = threading.Lock(), threading.Event()

        def work() -> None:
            try:
                while not stop.is_set():
                    with lock:
                        nxt = next(left, None)
                    if nxt is None:
                        return
                    tallies[nxt[0]] = _traced(self.ps, nxt[1])
            except BaseException:
                stop.set()  # the others take no further job
                raise

        helpers = [self.pool.submit(work) for _ in range(min(self.threads, len(jobs)) - 1)]
        try:
            work()
        finally:
            for f in helpers:
                f.result()
        return tallies

    def shutdown(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=True)
