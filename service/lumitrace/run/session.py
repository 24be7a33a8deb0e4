"""A tracing session: rounds of photon batches on a thread pool until a stop criterion.

Photons are shared among emitters in proportion to their flux, so all photons carry about
the same flux. Which photons an emitter traces depends only on the photon budget, never on
the number of threads or the batch size, so the same seed gives the same map anywhere.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from typing import Callable

from ..film.accumulate import Accumulator
from ..film.convergence import MapEstimate, estimate
from ..scene import Scene
from . import workers
from ..trace.tracer import MAX_DEPTH, PreparedScene, prepare

DEFAULT_PHOTONS = 2_000_000
DEFAULT_RESOLUTION = 64
#: Photon count from which a texel trusts its own estimate whatever its neighbours say
#: (pull-push threshold): 1 / 0.02**2, the count at which its own noise is 2%.
DEFAULT_THRESHOLD = 2500.0
#: Error below which a result counts as converged when no target is given.
DEFAULT_TARGET_ERROR = 0.02
#: Photons in the first iteration; later iterations double up to a full round of batches.
FIRST_ITERATION = 1 << 15


@dataclass(frozen=True)
class TraceSettings:
    """What to trace and when to stop: ``photons`` (total), ``seconds`` or ``target_error``
    (flux-weighted relative standard error); the first one reached stops the session."""

    photons: int | None = None
    seconds: float | None = None
    target_error: float | None = None
    resolution: int = DEFAULT_RESOLUTION
    threshold: float = DEFAULT_THRESHOLD
    seed: int = 0
    threads: int = field(default_factory=lambda: os.cpu_count() or 1)
    batch_size: int = 1 << 17
    max_depth: int = MAX_DEPTH
    workers: str = "auto"

    def budget(self) -> int | None:
        """Total photons to trace, or None when only time or error stops the session."""
        if self.photons is None and self.seconds is None and self.target_error is None:
            return DEFAULT_PHOTONS
        return self.photons


@dataclass
class Progress:
    """One iteration's state, passed to progress callbacks: the map estimate holds the raw
    and filtered maps (cd) and their estimated errors."""

    iteration: int
    photons: int
    seconds: float
    relative_error: float
    budget: int | None
    estimate: MapEstimate | None = None
    accumulator: Accumulator | None = None


@dataclass
class TraceResult:
    """The accumulated photons of a session and the maps estimated from them."""

    scene: Scene
    settings: TraceSettings
    accumulator: Accumulator
    iterations: int
    seconds: float
    prepare_seconds: float
    estimate: MapEstimate

    @property
    def photons(self) -> int:
        return self.accumulator.photons

    @property
    def relative_error(self) -> float:
        """Estimated relative RMS error of the map written as ``Y``."""
        return self.estimate.error

    @property
    def converged(self) -> bool:
        target = self.settings.target_error or DEFAULT_TARGET_ERROR
        return self.relative_error <= target


def allocate(fluxes: list[float], photons: int) -> list[int]:
    """Split ``photons`` among emitters in proportion to flux (largest remainder)."""
    total = float(sum(fluxes))
    exact = [photons * f / total for f in fluxes]
    base = [int(math.floor(x)) for x in exact]
    rest = photons - sum(base)
    order = sorted(range(len(fluxes)), key=lambda i: (base[i] - exact[i], i))
    for i in order[:rest]:
        base[i] += 1
    return base


def _round_jobs(done: list[int], targets: list[float], shares: list[float],
                round_photons: int, batch: int) -> list[tuple[int, int, int]]:
    """Jobs (emitter, first photon, count) of the next round, batch-sized."""
    jobs = []
    for e, (n_done, n_target, share) in enumerate(zip(done, targets, shares)):
        want = min(int(math.ceil(round_photons * share)), n_target - n_done)
        start = n_done
        while want > 0:
            c = int(min(batch, want))
            jobs.append((e, start, c))
            start += c
            want -= c
    return jobs


def run(scene: Scene, settings: TraceSettings, prepared: PreparedScene | None = None,
        progress: Callable[[Progress], None] | None = None) -> TraceResult:
    """Trace ``scene`` until the settings say stop; return the accumulated result."""
    t0 = time.perf_counter()
    ps = prepared or prepare(scene)
    t_prep = time.perf_counter() - t0
    acc = Accumulator(scene, settings.resolution)
    fluxes = [e.flux for e in scene.emitters]
    shares = [f / sum(fluxes) for f in fluxes]
    budget = settings.budget()
    targets = allocate(fluxes, budget) if budget is not None else [math.inf] * len(fluxes)
    done = [0] * len(fluxes)
    threads = max(1, int(settings.threads))
    full_round = threads * settings.batch_size * 2
    round_photons = min(FIRST_ITERATION, full_round)
    iteration = 0
    est = None

    mode = workers.choose(settings.workers, threads, budget)
    with workers.batch_runner(scene, ps, mode, threads, settings.seed, settings.resolution,
                              settings.max_depth) as trace_jobs:
        start = time.perf_counter()
        while True:
            jobs = _round_jobs(done, targets, shares, round_photons, settings.batch_size)
            if not jobs:
                break
            for tally in trace_jobs(jobs):
                acc.add(tally)
                done[tally.emitter] += tally.photons
            iteration += 1
            round_photons = min(2 * round_photons, full_round)
            est = estimate(acc, settings.threshold)
            elapsed = time.perf_counter() - start
            err = est.error
            if progress is not None:
                progress(Progress(iteration, acc.photons, elapsed, err, budget, est, acc))
            if settings.seconds is not None and elapsed >= settings.seconds:
                break
            if settings.target_error is not None and err <= settings.target_error:
                break
    if est is None:
        est = estimate(acc, settings.threshold)
    return TraceResult(scene=scene, settings=settings, accumulator=acc, iterations=iteration,
                       seconds=time.perf_counter() - start, prepare_seconds=t_prep, estimate=est)
