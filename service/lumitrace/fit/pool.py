"""Candidates traced side by side: on threads of this process, on worker processes, or on
the workers of a Dask scheduler. A candidate is one task (its photons are few: splitting it
would cost more in fixed work than it saves), so a generation of candidates keeps every
worker busy. Threads trace a candidate selectively from a base trace where that is cheaper
(:func:`~.measure.retrace_counts`); processes and Dask trace afresh. Every way gives the
same counts, so the same merits."""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

from ..errors import LumitraceError
from ..scene import Scene
from .measure import Base, Plan, make_base, measure_fresh, measurement, retrace_counts, \
    trace_counts
from .objective import Measurement, Needs

MODES = ("threads", "processes", "dask")


@dataclass(frozen=True)
class Traced:
    """A candidate's measurement, the photons retraced selectively (None: traced afresh)
    and the seconds its task took (on its worker)."""

    measurement: Measurement
    retraced: int | None
    seconds: float


def _fresh(scene: Scene, plan: Plan, photons: int, needs: Needs) -> Traced:
    t0 = time.perf_counter()
    m = measure_fresh(scene, plan, photons, needs)
    return Traced(m, None, time.perf_counter() - t0)


def _selective(base: Base | None, scene: Scene, plan: Plan, photons: int,
               needs: Needs) -> Traced:
    t0 = time.perf_counter()
    got = retrace_counts(base, scene, plan) if base is not None else None
    if got is None:
        acc, _ = trace_counts(scene, plan, photons)
        retraced = None
    else:
        acc, retraced = got
    return Traced(measurement(scene, acc, needs), retraced, time.perf_counter() - t0)


def _init_process() -> None:
    from ..run.workers import _detach_from_signals

    _detach_from_signals()


def _on_dask_worker(expected: tuple[str, str], scene: Scene, plan: Plan, photons: int,
                    needs: Needs) -> Traced:
    """A candidate on a Dask worker, refused where it runs another lumitrace."""
    from ..run.cluster import identity

    mine = identity()
    if tuple(mine) != tuple(expected):
        raise RuntimeError(f"this worker runs lumitrace {mine[0]} (tracer {mine[1]}), the "
                           f"client {expected[0]} (tracer {expected[1]})")
    return _fresh(scene, plan, photons, needs)


class Evaluator:
    """Traces candidates' scenes at a photon count and measures them, ``workers`` at a
    time, in ``mode`` (threads, processes or dask with ``scheduler``). On threads it keeps
    a base trace (with its photons' records) of :meth:`use_base`'s scene at each photon
    count, until a generation comes none of whose candidates it could retrace
    selectively."""

    def __init__(self, plan: Plan, needs: Needs, mode: str = "threads", workers: int = 1,
                 scheduler: str | None = None, selective: bool = True):
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        self.plan, self.needs, self.mode = plan, needs, mode
        self.workers = max(1, int(workers))
        self.selective = selective and mode == "threads"
        self.base: Base | None = None
        self.base_scene: Scene | None = None
        self._pool = None
        self._client = None
        if mode == "dask":
            from ..run.cluster import connect, identity, total_threads

            self._client = connect(scheduler)
            self._identity = identity()
            self.workers = total_threads(self._client)
        elif mode == "processes":
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self._pool = ProcessPoolExecutor(self.workers,
                                             mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_init_process)
        elif self.workers > 1:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(self.workers)

    def use_base(self, scene: Scene) -> None:
        """Trace candidates selectively from ``scene`` (made at the next photon count)."""
        self.base_scene = scene

    def evaluate(self, scenes: Sequence[Scene], photons: int) -> list[Traced]:
        """Every scene traced with ``photons`` and measured, in order."""
        if self.mode == "dask":
            futures = [self._client.submit(_on_dask_worker, self._identity, s, self.plan,
                                           photons, self.needs, pure=False) for s in scenes]
            try:
                return [f.result() for f in futures]
            except Exception as exc:  # noqa: BLE001 - one line naming the cluster
                self._client.cancel(futures)
                if isinstance(exc, LumitraceError):
                    raise
                raise LumitraceError(f"a candidate failed on the Dask cluster: {exc}",
                                     self._client.scheduler.address) from None
        if self.mode == "processes":
            futures = [self._pool.submit(_fresh, s, self.plan, photons, self.needs)
                       for s in scenes]
            return [f.result() for f in futures]
        if self.selective and self.base_scene is not None and (
                self.base is None or self.base.photons != photons):
            self.base = make_base(self.base_scene, self.plan, photons)
        base = self.base if self.selective else None
        if self._pool is None:
            out = [_selective(base, s, self.plan, photons, self.needs) for s in scenes]
        else:
            futures = [self._pool.submit(_selective, base, s, self.plan, photons,
                                         self.needs) for s in scenes]
            out = [f.result() for f in futures]
        if base is not None and all(t.retraced is None for t in out):
            # every candidate of the generation changed too much (a material most light
            # meets, a part most light hits): no base is kept at the next photon counts
            self.selective, self.base = False, None
        return out

    def close(self) -> None:
        if self._pool is not None:
            if self.mode == "processes":
                from ..run.workers import _end_pool

                _end_pool(self._pool)
            else:
                self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._client is not None:
            import contextlib

            with contextlib.suppress(Exception):
                self._client.close(timeout=5)
            self._client = None
