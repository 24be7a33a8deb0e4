"""The thread pool's rounds: traced in the calling thread while that is cheaper, shared with
the pool's threads when a round is worth it, the same tallies in job order either way."""
from __future__ import annotations

import numpy as np
import pytest

from lumitrace.film.accumulate import _nonzero
from lumitrace.run import workers
from lumitrace.stage.reader import read_stage
from lumitrace.trace.job import BatchJob
from lumitrace.trace.prepared import prepare
from helpers.paths import ROOT


@pytest.fixture(scope="module")
def prepared():
    return prepare(read_stage(ROOT / "stages" / "downlight.usda"))


def _jobs(emitters: int, per_job: int = 3000, jobs_each: int = 3) -> list[BatchJob]:
    return [BatchJob(e, k * per_job, per_job, 5, 16, 50)
            for e in range(emitters) for k in range(jobs_each)]


def _same(a, b) -> None:
    assert [(t.emitter, t.start, t.photons) for t in a] == \
        [(t.emitter, t.start, t.photons) for t in b]
    for x, y in zip(a, b):  # dense or sparse, the same texels and cells with the same counts
        for u, v in ((x.counts, y.counts), (x.cells, y.cells)):
            for p, q in zip(_nonzero(u), _nonzero(v)):
                assert np.array_equal(p, q)
        assert (x.absorbed, x.cut, x.segments) == (y.absorbed, y.cut, y.segments)


def test_a_cheap_round_never_starts_the_pool(prepared):
    jobs = _jobs(len(prepared.scene.emitters), per_job=1000)
    expected = [workers._traced(prepared, j) for j in jobs]  # (kernels warm: a fair rate)
    pool = workers._ThreadPool(prepared, 2)
    try:
        first = list(pool(jobs))  # the first job alone gives the rate; the rest is cheap
        assert pool.pool is None  # 2,000 photons left: a few milliseconds
        assert pool.seconds_per_photon is not None and pool.seconds_per_photon > 0
    finally:
        pool.shutdown()
    _same(first, expected)


def test_a_round_is_split_when_the_run_is_worth_the_pool_and_the_round_worth_a_split(
        prepared):
    pool = workers._ThreadPool(prepared, 2)
    assert pool.ways(1000) == 2  # no rate yet: split, its first job traced alone
    pool.seconds_per_photon = 1e-6
    assert workers.INLINE_SECONDS < 0.02 < workers.START_POOL_SECONDS
    assert pool.ways(20_000) == 1  # 20 ms, and nothing known of the run beyond it
    assert pool.ways(20_000, remaining=10_000) == 1
    assert pool.ways(20_000, remaining=1_000_000) == 2  # a second's work left: start it
    assert pool.ways(5_000, remaining=1_000_000) == 1  # a round too small to split
    assert pool.ways(60_000) == 2
    assert workers._ThreadPool(prepared, 1).ways(10**9) == 1


def test_a_round_worth_it_is_shared_with_the_pool_and_tallies_the_same(prepared,
                                                                        monkeypatch):
    jobs = _jobs(len(prepared.scene.emitters), jobs_each=5)
    inline = workers._ThreadPool(prepared, 1)
    expected = list(inline(jobs))
    monkeypatch.setattr(workers, "START_POOL_SECONDS", 0.0)
    monkeypatch.setattr(workers, "INLINE_SECONDS", 0.0)
    pool = workers._ThreadPool(prepared, 3)
    try:
        shared = list(pool(jobs))  # the first job alone (the rate), the rest shared
        assert pool.pool is not None and pool.pool._max_workers == 2
        names = set()
        monkeypatch.setattr(workers, "_traced", _naming(workers._traced, names))
        again = list(pool(jobs))
        assert len(names) >= 2  # this thread and at least one of the pool's took jobs
    finally:
        pool.shutdown()
    _same(shared, expected)
    _same(again, expected)


def _naming(traced, names: set):
    import threading

    def wrapped(ps, job):
        names.add(threading.current_thread().name)
        return traced(ps, job)
    return wrapped


def test_an_error_in_a_shared_round_is_raised_and_stops_the_round(prepared, monkeypatch):
    monkeypatch.setattr(workers, "START_POOL_SECONDS", 0.0)
    monkeypatch.setattr(workers, "INLINE_SECONDS", 0.0)
    jobs = _jobs(len(prepared.scene.emitters), jobs_each=8)
    taken = []
    traced = workers._traced

    def failing(ps, job):
        taken.append(job)
        if len(taken) == 3:
            raise RuntimeError("batch failed")
        return traced(ps, job)

    pool = workers._ThreadPool(prepared, 2)
    pool.seconds_per_photon = 1.0  # a known rate: the whole round is shared
    monkeypatch.setattr(workers, "_traced", failing)
    try:
        with pytest.raises(RuntimeError, match="batch failed"):
            list(pool(jobs))
    finally:
        pool.shutdown()
    assert len(taken) <= 4 < len(jobs)  # at most the job each thread had in hand after it
