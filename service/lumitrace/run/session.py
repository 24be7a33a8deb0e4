"""A tracing session: rounds of photon batches on a thread pool until a stop criterion.

Photons are shared among emitters in proportion to their flux, so all photons carry about
the same flux. Which photons an emitter traces depends only on the photon budget, never on
the number of threads or the batch size, so the same seed gives the same map anywhere.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

from ..errors import warn
from ..film.accumulate import Accumulator
from ..film.convergence import MapEstimate, estimate
from ..scene import Scene
from ..trace.job import BatchJob
from ..trace.prepared import PreparedScene, TracingFrame, prepare
from . import workers
from .settings import TraceSettings

#: Photons in the first iteration; later iterations double up to a full round of batches.
FIRST_ITERATION = 1 << 15
#: A session stopped only by time or error ends once this many photons left no light
#: outside the luminaire: its error is undefined and would never reach a target.
NO_ESCAPE_PHOTONS = 1 << 20
#: Share of the emitted flux cut by the depth limit above which the result says so.
CUT_WARNING_FRACTION = 0.01


@dataclass(frozen=True)
class Progress:
    """One iteration's state, passed to progress callbacks: the map estimate holds the raw
    and filtered maps (cd) and their estimated errors; ``accumulator`` is a snapshot that
    the session never changes afterwards."""

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
        return self.relative_error <= self.settings.convergence_target


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
                round_photons: int, settings: TraceSettings) -> list[BatchJob]:
    """Batch jobs of the next round, batch-sized."""
    batch = settings.batch_size
    jobs = []
    for e, (n_done, n_target, share) in enumerate(zip(done, targets, shares)):
        want = min(int(math.ceil(round_photons * share)), n_target - n_done)
        start = n_done
        while want > 0:
            c = int(min(batch, want))
            jobs.append(BatchJob(e, start, c, settings.seed, settings.resolution,
                                 settings.max_depth))
            start += c
            want -= c
    return jobs


def _warn_cut(acc: Accumulator, settings: TraceSettings) -> None:
    """Warn when the depth limit cut a noticeable share of the emitted flux."""
    f = acc.fluxes()
    if f["emitted"] > 0 and f["cut"] > CUT_WARNING_FRACTION * f["emitted"]:
        warn(f"{f['cut'] / f['emitted']:.1%} of the emitted flux was cut by the depth limit "
             f"({settings.max_depth} bounces): the light output ratio and the map lack it; "
             "raise the depth limit or check for a light trap")


def run(scene: Scene, settings: TraceSettings, prepared: PreparedScene | None = None,
        progress: Callable[[Progress], None] | None = None,
        frame: TracingFrame | None = None) -> TraceResult:
    """Trace ``scene`` until the settings say stop; return the accumulated result.

    ``frame`` pins the normalised tracing frame (default: the scene's own bounds);
    ``progress`` is called after every iteration with an immutable snapshot.
    """
    t0 = time.perf_counter()
    ps = prepared or prepare(scene, frame)
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
    with workers.batch_runner(scene, ps, mode, threads) as trace_jobs:
        start = time.perf_counter()
        while True:
            jobs = _round_jobs(done, targets, shares, round_photons, settings)
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
                progress(Progress(iteration, acc.photons, elapsed, err, budget, est,
                                  acc.snapshot()))
            if settings.seconds is not None and elapsed >= settings.seconds:
                break
            if settings.target_error is not None and err <= settings.target_error:
                break
            if budget is None and acc.photons >= NO_ESCAPE_PHOTONS and not any(t.escaped for t in acc.emitters):
                warn(f"no light escaped the luminaire in {acc.photons:,} photons: stopping "
                     "(light output ratio 0, the map's error is undefined)")
                break
    if est is None:
        est = estimate(acc, settings.threshold)
    _warn_cut(acc, settings)
    return TraceResult(scene=scene, settings=settings, accumulator=acc, iterations=iteration,
                       seconds=time.perf_counter() - start, prepare_seconds=t_prep, estimate=est)
