"""A tracing session: rounds of photon batches on a thread pool until a stop criterion.

Photons are shared among emitters in proportion to their flux, so all photons carry about
the same flux. Which photons an emitter traces depends only on the photon budget, never on
the number of threads or the batch size, so the same seed gives the same map anywhere.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Callable

from ..errors import ClusterLost, LumitraceError, warn
from ..film.accumulate import Accumulator, flux_scale
from ..film.goniometer import Goniometer
from ..film.convergence import MapEstimate, estimate
from ..scene import Scene
from ..film.result import TraceResult
from ..photometry.accuracy import FilesAccuracy
from ..photometry.distribution import files_accuracy
from ..trace.allocation import MIN_EMITTER_PHOTONS, allocate
from ..trace.job import BatchJob
from ..trace.prepared import PreparedScene, TracingFrame, prepare
from ..trace.records import PhotonRecords
from . import workers
from .memory import check_memory
from .settings import TraceSettings

#: Photons in the first iteration; later iterations double up to a full round of batches,
#: and on while estimating the map costs more than :data:`ESTIMATE_SHARE` of tracing a
#: round that takes less than :data:`ROUND_SECONDS`: the estimate stays a small part of a
#: run whatever the tracer's speed, and a round stays short enough for an edit to wait.
FIRST_ITERATION = 1 << 15
ESTIMATE_SHARE = 0.1
ROUND_SECONDS = 1.0
#: Share of ``--time`` left at which a session stops rather than start a round (rounds are
#: sized to end by the deadline at the rate measured so far).
DEADLINE_SLACK = 0.02
#: A session stopped only by time or error ends once this many photons left no light
#: outside the luminaire: its error is undefined and would never reach a target.
NO_ESCAPE_PHOTONS = 1 << 20
#: Photons a session traces before the map's estimated error may stop it: the split-half
#: estimate of the first small rounds can be far too low (few photons per texel).
MIN_PHOTONS_FOR_TARGET = 1 << 17
#: The same for a target judged on the files: their cells' variances are the counts' own
#: (binomial), so the judged error holds from the first rounds (on four reference stages,
#: ten seeds, at 32,768 to 98,304 photons its median was 0.95-1.04 of the true error, as
#: at 229,376); this many photons guard against a beam no photon has found yet.
MIN_PHOTONS_FOR_FILES_TARGET = 1 << 16
#: A files' target's last round is sized to reach it (the error falling as one over the
#: root of the photons) with this many times the photons projected, not doubled blindly:
#: the estimate is noisy, most in the worst lit value, and a round short of the target
#: costs another round's judging.
TARGET_MARGIN = 1.2
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
    #: the map's estimated error (the files' judged error where the map was not estimated)
    relative_error: float
    budget: int | None
    estimate: MapEstimate | None = None
    accumulator: Accumulator | None = None
    #: the photometric files' accuracy where the target is judged on them
    files: FilesAccuracy | None = None


#: With a photon budget alone, an emitter's job in a round holds at least this many photons
#: (or all it has left): a scene of thousands of small lights is not split into tens of
#: thousands of jobs of a few photons, each with its fixed cost. (A time limit or a target
#: error keeps the small first rounds: they must stop on time.)
MIN_JOB_PHOTONS = 256


#: A round smaller than a batch per thread is split among the threads in jobs of at
#: least this many photons.
MIN_SPLIT_PHOTONS = 4096


#: A round's last jobs are cut to halves and then quarters of a batch, each size once per
#: thread, down to no less than this many photons: the threads take the next job left, so
#: they end a round within a small job of each other (whole batches to the end left one
#: thread waiting for up to a batch at every round).
TAPER_PHOTONS = 32768


def _tapered(jobs: list[BatchJob], threads: int, batch: int) -> list[BatchJob]:
    """``jobs`` with their last photons cut into smaller jobs (see :data:`TAPER_PHOTONS`),
    in the same order; the photons and so the counts are the same."""
    sizes = [size for size in (batch // 4, batch // 2) if size >= TAPER_PHOTONS
             for _ in range(threads)]  # from the round's end
    if len(jobs) < 2 or not sizes:
        return jobs
    jobs, tail = list(jobs), []
    while jobs and sizes:
        job = jobs.pop()
        stop = job.first + job.count
        while sizes and stop > job.first:
            cut = min(sizes.pop(0), stop - job.first)
            tail.append(replace(job, first=stop - cut, count=cut))
            stop -= cut
        if stop > job.first:
            tail.append(replace(job, count=stop - job.first))
    return jobs + tail[::-1]


def _round_jobs(done: list[int], targets: list[float], shares: list[float],
                round_photons: int, settings: TraceSettings,
                ways: int | None = None) -> list[BatchJob]:
    """Batch jobs of the next round, batch-sized, or split ``ways`` ways (default: among
    the threads) where the round is smaller than a batch a way (a first round on one core
    of two took twice its time); jobs of at least :data:`MIN_SPLIT_PHOTONS`, the last ones
    smaller on more than one thread (:func:`_tapered`). The counts are the same for any
    split."""
    threads = max(1, int(ways or settings.threads))
    batch = min(settings.batch_size, max(MIN_SPLIT_PHOTONS, -(-round_photons // threads)))
    floor = MIN_JOB_PHOTONS if settings.seconds is None and settings.target_error is None \
        else 0
    jobs = []
    for e, (n_done, n_target, share) in enumerate(zip(done, targets, shares)):
        want = min(max(int(math.ceil(round_photons * share)), floor), n_target - n_done)
        start = n_done
        while want > 0:
            c = int(min(batch, want))
            jobs.append(BatchJob(e, start, c, settings.seed, settings.resolution,
                                 settings.max_depth))
            start += c
            want -= c
    return _tapered(jobs, threads, batch) if threads > 1 else jobs


def photons_to_target(photons: int, error: float, target: float,
                      margin: float = TARGET_MARGIN) -> float:
    """Photons still to trace for a relative ``error`` measured at ``photons`` to fall to
    ``target``, errors falling as one over the root of the photons: ``margin`` times the
    photons projected, less those traced (infinite where the error is unknown)."""
    if not (math.isfinite(error) and error > 0 and target > 0 and photons > 0):
        return math.inf
    if error <= target:
        return 0.0
    return max(0.0, math.ceil(photons * margin * (error / target) ** 2) - photons)


def _warn_unreached(acc: Accumulator) -> None:
    """Warn about parts no photon reached: they cost triangles and change nothing."""
    unreached = acc.unreached_parts() if acc.photons else None
    if unreached:
        more = f" and {len(unreached) - 3} more" if len(unreached) > 3 else ""
        warn(f"{len(unreached)} part(s) no traced photon reached: "
             f"{', '.join(unreached[:3])}{more} (fully enclosed, behind an absorber, or "
             "out of the light's way)")


def _warn_cut(acc: Accumulator, settings: TraceSettings) -> None:
    """Warn when the depth limit cut a noticeable share of the emitted flux."""
    f = acc.fluxes()
    if f["emitted"] > 0 and f["cut"] > CUT_WARNING_FRACTION * f["emitted"]:
        warn(f"{f['cut'] / f['emitted']:.1%} of the emitted flux was cut by the depth limit "
             f"({settings.max_depth} bounces): the light output ratio and the map lack it; "
             "raise the depth limit or check for a light trap")


class Refinement:
    """The progressive state of one scene: its accumulator, the photons each emitter has
    traced and the iteration count. :meth:`step` traces one round of batches; the service
    drives it round by round (and drops it when the scene changes), :func:`run` to the end."""

    def __init__(self, scene: Scene, settings: TraceSettings,
                 first_round: int = FIRST_ITERATION, records_cap: int | None = None,
                 goniometer: Goniometer | None = None):
        """``records_cap`` (bytes): keep per-photon records for selective retracing (see
        :mod:`lumitrace.run.incremental`) up to this size, then drop them. ``goniometer``:
        the one the tracer counts with (the prepared scene's; default the scene's own)."""
        self.scene = scene
        self.records_cap = records_cap
        self.records: list[PhotonRecords] | None = (
            [PhotonRecords.empty() for _ in scene.emitters] if records_cap else None)
        self.records_dropped = False
        self.accumulator = Accumulator(scene, settings.resolution, goniometer)
        fluxes = [e.flux for e in scene.emitters]
        total = sum(fluxes)  # once: ten thousand emitters summed per emitter took 0.7 s
        self.shares = [f / total for f in fluxes]
        self.retarget(settings)
        self.done = [0] * len(fluxes)
        threads = max(1, int(settings.threads))
        self.full_round = threads * settings.batch_size * 2
        self.round_photons = min(first_round, self.full_round)
        self.iteration = 0
        self.estimate: MapEstimate | None = None
        self._estimated_version = self.accumulator.version  # the counts it is of
        self._t_trace = 0.0  # seconds the last round's tallies took to come
        self.files: FilesAccuracy | None = None
        self._files_photons = 0  # the photons self.files was judged at
        #: :attr:`estimate` was scaled from the last one by a rescale, not made afresh
        self._scaled_estimate = False

    def next_jobs(self, most: int | None = None,
                  ways: Callable[[int, float | None], int] | None = None) -> list[BatchJob]:
        """The batch jobs of the next round (empty when the photon budget is spent), of at
        most ``most`` photons when given (a round that must end by a deadline, ``most``
        the photons its time allows); ``ways(photons, photons left to the run or None)``
        says how many ways to split a round (default: among the threads)."""
        size = self.round_photons if math.isinf(self.to_target) else \
            max(MIN_SPLIT_PHOTONS, min(self.round_photons, int(self.to_target)))
        size = size if most is None else max(1, min(size, most))
        left = self.budget - self.accumulator.photons if self.budget is not None else \
            self.to_target if not math.isinf(self.to_target) else most
        return _round_jobs(self.done, self.targets, self.shares, size, self.settings,
                           ways and ways(size, left))

    def add_round(self, tallies, estimated: bool = True) -> MapEstimate | None:
        """Add a round's tallies; estimate the map and its error, unless not ``estimated``
        (nobody looks at it before the end: :meth:`result` estimates then). The tallies are
        all traced before any is added: adding while the tracing threads run makes every
        small step of the many small additions of a many-emitter scene wait for the GIL."""
        self.add_counts(tallies)
        return self.settle(estimated)

    def add_counts(self, tallies) -> None:
        """The first half of :meth:`add_round`: the round's counts in (what a lock around a
        refinement other threads read must cover); :attr:`estimate` is then of the counts
        before, until :meth:`settle` (:meth:`estimate_current` says which)."""
        t0 = time.perf_counter()
        tallies = list(tallies)
        self._t_trace = time.perf_counter() - t0
        for tally in tallies:
            self.accumulator.add(tally)
            self.done[tally.emitter] += tally.photons
            if self.records is not None:
                self._keep_records(tally)
        self.iteration += 1

    def settle(self, estimated: bool = True,
               checkpoint: Callable[[], None] = lambda: None) -> MapEstimate | None:
        """The second half of :meth:`add_round`: the map's estimate (unless not
        ``estimated``), the files judged where the target is theirs, the next round's
        size. It reads the counts only. ``checkpoint`` runs between its steps and may raise
        to abandon it: :attr:`estimate` then stays of the counts before (as
        :meth:`estimate_current` says), and whoever reads it next estimates afresh."""
        t0 = time.perf_counter()
        self.files = None
        est = estimate(self.accumulator, self.settings.threshold, checkpoint) \
            if estimated else None
        if est is not None and est.threshold != self.settings.threshold:
            est = estimate(self.accumulator, self.settings.threshold)  # changed meanwhile
        self._set_estimate(est)
        self.to_target = math.inf
        # the first rounds' estimates can be far too low: no projection from them (and
        # the files are not judged for it: 5-10 ms a round)
        if self.settings.target_error is not None and \
                self.accumulator.photons >= self._least_photons():
            checkpoint()
            files = self.current_files()
            if files is not None:
                self.to_target = photons_to_target(self.accumulator.photons, files.error,
                                                   self.settings.target_error)
        t_estimate = time.perf_counter() - t0
        if self.round_photons < self.full_round or (
                t_estimate > ESTIMATE_SHARE * self._t_trace and self._t_trace < ROUND_SECONDS):
            self.round_photons *= 2
        return self.estimate

    def _set_estimate(self, est: MapEstimate | None, scaled: bool = False) -> None:
        self.estimate, self._scaled_estimate = est, scaled
        self._estimated_version = self.accumulator.version

    def estimate_current(self) -> MapEstimate | None:
        """:attr:`estimate` where it is of the counts as they are, else None."""
        return self.estimate if self._estimated_version == self.accumulator.version else None

    def _keep_records(self, tally) -> None:
        rec = self.records[tally.emitter]
        if tally.records is None or len(rec) != tally.start:
            raise ValueError(f"records of emitter {tally.emitter} do not follow on at photon "
                             f"{tally.start}")
        self.records[tally.emitter] = rec.extend(tally.records)
        if sum(r.nbytes for r in self.records) > self.records_cap:
            self.records, self.records_dropped = None, True

    def retarget(self, settings: TraceSettings) -> None:
        """Take stop criteria and threshold (at the start, or when a service's client
        changes them): the photons traced stay, and the budget, if any, is shared among
        the emitters, each getting at least :data:`MIN_EMITTER_PHOTONS`. A budget too
        small for that is refused before anything changes."""
        budget = settings.budget()
        fluxes = [e.flux for e in self.scene.emitters]
        if budget is not None and budget < MIN_EMITTER_PHOTONS * len(fluxes):
            raise LumitraceError(
                f"{budget:,} photons are too few for {len(fluxes):,} emitters: each "
                f"needs at least {MIN_EMITTER_PHOTONS} photon, so trace at least "
                f"{MIN_EMITTER_PHOTONS * len(fluxes):,} (--photons)", self.scene.luminaire_path)
        self.targets = (allocate(fluxes, budget, MIN_EMITTER_PHOTONS)
                        if budget is not None else [math.inf] * len(fluxes))
        self.settings, self.budget = settings, budget
        #: photons the files' target is projected to need beyond those traced (infinite:
        #: none projected): the next round is no larger (see :data:`TARGET_MARGIN`)
        self.to_target = math.inf

    def finished(self) -> bool:
        """Whether refining is over: the target reached, the budget spent, or no light
        escaping."""
        return self.reached_target() or self.no_escape() or not self.next_jobs()

    def reestimate(self) -> MapEstimate:
        """Estimate the map again (after photons were retraced)."""
        self._set_estimate(estimate(self.accumulator, self.settings.threshold))
        self.files = None  # judged again when asked: the counts changed
        return self.estimate

    def current_files(self) -> FilesAccuracy | None:
        """:meth:`judge_files`, measured once per photon count (a service's status asks
        for it at every poll; rescales and retraces drop it)."""
        if self.files is None or self._files_photons != self.accumulator.photons:
            self.files = self.judge_files()
            self._files_photons = self.accumulator.photons
        return self.files

    def judge_files(self) -> FilesAccuracy | None:
        """The photometric files' accuracy from the counts so far, where the settings judge
        the target on the files (None where they judge it on the map)."""
        if self.settings.target_of != "files":
            return None
        return files_accuracy(self.scene, self.accumulator)

    def _least_photons(self) -> int:
        """Photons traced before the target may stop the session (or size its rounds)."""
        return MIN_PHOTONS_FOR_FILES_TARGET if self.settings.target_of == "files" else \
            MIN_PHOTONS_FOR_TARGET

    def reached_target(self) -> bool:
        """Whether the target error (the settings') is met, once
        :meth:`_least_photons` are traced: by the files (RMS bound and worst
        lit value) or by the map's estimated error bound, as the settings say."""
        t = self.settings.target_error
        if t is None or self.accumulator.photons < self._least_photons():
            return False
        if self.settings.target_of == "files":
            return self.files is not None and self.files.meets(t)
        return self.estimate is not None and self.estimate.meets(t)

    def judged(self) -> tuple[str, float | None, bool]:
        """(what the target is judged on, the judged error, converged at the settings'
        convergence target) from the last round: the files' accuracy or the map's bound."""
        target = self.settings.convergence_target
        if self.settings.target_of == "files":
            files = self.current_files()
            return "files", files.error, files.meets(target)
        est = self.estimate
        return "map", est.error_bound if est else None, bool(est and est.meets(target))

    def no_escape(self) -> bool:
        """True once a session without a photon budget has traced
        :data:`NO_ESCAPE_PHOTONS` photons and none of them left the luminaire."""
        acc = self.accumulator
        return (self.budget is None and acc.photons >= NO_ESCAPE_PHOTONS
                and not any(t.escaped for t in acc.emitters))

    def rescale(self, scene: Scene) -> None:
        """Take ``scene``, which differs from this one in emitter fluxes (and, with no
        coloured surface, lights' colours) only: the counts stay and scale with the new
        fluxes (photons are analog), the lights' colours are taken, nothing is retraced."""
        acc = self.accumulator
        before, current = acc.light_state(), self.estimate_current() is not None
        for i, e in enumerate(scene.emitters):
            acc.rescale(i, e.flux)
        acc.colour = scene.colour
        acc.set_colours(scene)
        self.scene = scene
        k = flux_scale(before, acc.light_state())
        if k is not None and current:
            # every light dimmed alike (one light, say): the maps scale, at once; the
            # files' estimate is made afresh from the counts (:meth:`result`)
            self._set_estimate(self.estimate.scaled(k), scaled=True)
        elif current:
            self._set_estimate(estimate(acc, self.settings.threshold))
        # else the counts' estimate was given up (:meth:`settle`): it stays to be made by
        # whoever reads it next
        self.files = None  # judged again when asked: the fluxes changed

    def result(self, seconds: float, prepare_seconds: float = 0.0,
               frozen: bool = False) -> TraceResult:
        """The result of the counts as they are; ``frozen``: of a copy of them, for another
        thread to write while they grow, its map estimated there where the estimate is not
        current or a rescale's (:meth:`TraceResult.estimated`)."""
        exact = self.estimate_current() is not None and not self._scaled_estimate
        if frozen:
            return replace(self._result(seconds, prepare_seconds),
                           accumulator=self.accumulator.snapshot(),
                           estimate=self.estimate if exact else None)
        if not exact:
            self._set_estimate(estimate(self.accumulator, self.settings.threshold))
        return self._result(seconds, prepare_seconds)

    def _result(self, seconds: float, prepare_seconds: float) -> TraceResult:
        est = self.estimate
        # the files' accuracy of the last round, where no photon came since; else the
        # writer measures it from the grid it writes (a scene of thousands of lights pays
        # for measuring the grid once, not twice)
        files = self.files if self.files is not None and \
            self._files_photons == self.accumulator.photons else None
        return TraceResult(scene=self.scene, settings=self.settings,
                           accumulator=self.accumulator, iterations=self.iteration,
                           seconds=seconds, prepare_seconds=prepare_seconds, estimate=est,
                           files_accuracy=files,
                           judge_files=self.settings.target_of == "files")


def run(scene: Scene, settings: TraceSettings, prepared: PreparedScene | None = None,
        progress: Callable[[Progress], None] | None = None,
        frame: TracingFrame | None = None, clock_start: float | None = None,
        progress_maps: bool = True) -> TraceResult:
    """Trace ``scene`` until the settings say stop; return the accumulated result.

    ``frame`` pins the normalised tracing frame (default: the scene's own bounds);
    ``progress`` is called after every iteration with an immutable snapshot (with the map
    estimate unless not ``progress_maps``: a caller that shows the files' error alone does
    not pay for the map's every round);
    ``clock_start`` (``time.perf_counter``) is when ``settings.seconds`` started to count
    (default: now; the command line counts from its own start).
    """
    check_memory(len(scene.emitters), settings.resolution, settings.threads, settings.budget())
    t0 = time.perf_counter()
    ps = prepared or prepare(scene, frame)
    t_prep = time.perf_counter() - t0
    r = Refinement(scene, settings, goniometer=ps.goniometer)
    threads = max(1, int(settings.threads))
    mode = "dask" if settings.scheduler else workers.choose(settings.workers, threads, r.budget)
    lost = None
    with workers.batch_runner(scene, ps, mode, threads, settings.scheduler) as trace_jobs:
        if mode == "dask":  # a full round keeps every thread of the cluster busy
            r.full_round = trace_jobs.threads * settings.batch_size * 2
        start = time.perf_counter()
        deadline = None if settings.seconds is None else \
            (clock_start if clock_start is not None else start) + settings.seconds
        # a round's map estimate serves the progress shown and a target judged on the map
        estimated = (progress is not None and progress_maps) or (
            settings.target_error is not None and settings.target_of == "map")
        while True:
            most = None
            if deadline is not None and r.iteration:
                # a round sized to end by the deadline, at the rate of the rounds so far
                now = time.perf_counter()
                left = deadline - now
                if left <= DEADLINE_SLACK * settings.seconds:
                    break
                most = int(r.accumulator.photons / max(now - start, 1e-9) * left)
            jobs = r.next_jobs(most, getattr(trace_jobs, "ways", None))
            if not jobs:
                break
            try:
                est = r.add_round(trace_jobs(jobs), estimated)
            except ClusterLost as exc:  # keep the batches that finished, then say so
                est, lost = r.add_round(exc.tallies, True), exc
                break
            elapsed = time.perf_counter() - start
            if progress is not None:
                judged = r.current_files()
                error = est.error if est is not None else \
                    judged.error if judged is not None else math.inf
                progress(Progress(r.iteration, r.accumulator.photons, elapsed, error,
                                  r.budget, est, r.accumulator.snapshot(), judged))
            if deadline is not None and time.perf_counter() >= deadline:
                break
            if r.reached_target():
                break
            if r.no_escape():
                warn(f"no light escaped the luminaire in {r.accumulator.photons:,} photons: "
                     "stopping (light output ratio 0, the map's error is undefined)")
                break
    _warn_cut(r.accumulator, settings)
    _warn_unreached(r.accumulator)
    result = r.result(time.perf_counter() - start, t_prep)
    result.batches_redone = getattr(trace_jobs, "redone", 0)
    if result.batches_redone:
        warn(f"{result.batches_redone} batch(es) sent again after a Dask worker was lost "
             "(the result is the same)")
    if lost is not None and not result.photons:
        raise LumitraceError(f"{lost.message} before any batch finished: nothing was "
                             "written", lost.where)
    if lost is not None:
        lost.result = result
        raise lost
    return result
