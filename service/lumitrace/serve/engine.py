"""The service's tracing engine: one thread refining the newest revision round by round.

A new revision abandons the round in flight (its photons are dropped, never mixed into the
new revision's map); a burst of revisions coalesces into the newest. A flux-only edit
rescales the counts and traces nothing. Results are written after a revision's first
iteration, then at most every :data:`WRITE_INTERVAL` seconds, and with the pictures once
the revision is done (converged or its photon budget spent) or the service stops; a done
revision's are drawn by the writer thread, so an edit made meanwhile is traced at once.
"""
from __future__ import annotations

import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable

from ..delta.effect import EFFECT_KINDS, classify
from ..errors import LumitraceError
from ..publish.outputs import write_outputs
from ..publish.record import ResultRecord, defined
from ..run.incremental import Selection, retrace, select
from ..run.session import Refinement
from ..run.settings import TraceSettings, with_knobs
from ..trace.prepared import TracingFrame, prepare
from ..trace.tracer import trace_batch
from .events import EventLog
from .live import LiveStage, Revision
from .writer import Writer

#: Iterations of a revision after each of which the cheap outputs are written (more: an
#: edit made while they are written waits for them, on the demo 85 ms each).
EAGER_WRITES = 1
#: Seconds between writes of the cheap outputs after the first iterations.
WRITE_INTERVAL = 2.0
#: Revisions closer together than this (s) are a burst: the engine then waits for
#: :data:`BURST_QUIET` s without a new one (at most :data:`BURST_WAIT` s) before tracing,
#: so that a burst costs a few restarts, while a single edit starts at once. It is about
#: the time a revision takes to its first preview on the demo (60-100 ms): edits further
#: apart each get their preview before the next comes, so waiting would only delay them.
BURST_GAP = 0.1
BURST_QUIET = 0.05
BURST_WAIT = 0.5
#: After a flux-only edit the refinement waits until this many seconds passed without a
#: new revision: a designer dragging a flux slider gets each edit's preview and files
#: without the tracing beside them (each such edit's files in 65-70 ms, not 100-130).
RESCALE_QUIET = 0.25
#: The pictures of a done revision are drawn once this many seconds passed without a new
#: revision (drawing takes seconds, and an edit would wait for it).
PICTURES_QUIET = 1.0
#: Bytes of per-photon records kept for selective retracing (40 bytes a photon: 1 GiB
#: holds about 27 million photons); above it, an edit restarts the trace.
RECORDS_CAP = 1 << 30
#: Above this share of the traced photons, an edit is traced afresh rather than retraced:
#: both give the same map, and a fresh trace shows its first result within one small round.
RETRACE_MAX_SHARE = 0.5
#: Photons per batch at most in the service's own rounds (about 25 ms of one thread's work):
#: what an edit may wait for.
SERVICE_BATCH = 1 << 15
#: Photons of a revision's first round: small, so that the first result after an edit is
#: on disk quickly (later rounds double up to a full round of batches).
FIRST_ROUND = 8192


class Engine:
    """Refines :attr:`revision` in a thread; :meth:`submit` hands it a newer one."""

    def __init__(self, live: LiveStage, settings: TraceSettings, events: EventLog,
                 out_dir: Path | None = None, records_cap: int = RECORDS_CAP,
                 sublayer: bool = True, deliverables: bool = False):
        self.live = live
        # an edit waits for the batches running when it comes: small ones (the counts are
        # the same for any batch size, and the rounds still grow with the photons)
        self.settings = replace(settings, workers="threads",
                                batch_size=min(settings.batch_size, SERVICE_BATCH))
        self.events = events
        self.out_dir = out_dir
        #: False: the result layer is written but not sublayered into the stage file
        self.sublayer = sublayer
        #: the datasheet and the GLDF container are written with each revision's pictures
        self.deliverables = deliverables
        #: called (on the engine's thread) once an edit's map is refreshed, before its
        #: files are written: the live view makes its preview frame then
        self.refreshed: Callable[[], Any] | None = None
        self._cv = threading.Condition()
        self._pending: Revision | None = None
        self._arrivals: list[float] = [0.0, 0.0]  # the last two submit times
        self._rescaled_at = -math.inf  # when the revision refined was taken as a rescale
        self._stopping = False
        self._thread = threading.Thread(target=self._main, name="lumitrace-engine",
                                        daemon=True)
        self._writer = Writer(self._write_failed)
        # state, read by status() under the lock
        self.revision: Revision | None = None
        self.refinement: Refinement | None = None
        self.done = False
        self.started = 0.0
        self.written: dict[str, Any] = {}
        self.record: ResultRecord | None = None
        self._last_write = 0.0
        self._written_full = False
        #: the revision whose pictures the writer is drawing (an edit need not wait for them)
        self._pictures_for: int | None = None
        self.error: str | None = None
        #: a revision failed: nothing is refined until the next one (the last result
        #: written stays served), and the next one is traced afresh
        self._halted = False
        #: the session's pinned tracing frame (set by the first revision)
        self.frame: TracingFrame | None = None
        #: paused by a client: nothing is traced until it resumes (edits are still taken)
        self.paused = False
        self.records_cap = records_cap
        #: the Dask cluster the rounds run on (``settings.scheduler``), None: this process
        self._cluster = None
        if self.settings.scheduler:
            from ..run.cluster import ClusterRunner, connect

            self._cluster = ClusterRunner(connect(self.settings.scheduler))
            # a full round keeps the cluster's threads busy
            self.settings = replace(self.settings, threads=self._cluster.threads)

    # -- control (any thread) -----------------------------------------------------------

    def start(self, first: Revision) -> None:
        self._pending = first
        self._thread.start()

    def submit(self, revision: Revision) -> None:
        """Make ``revision`` the one to refine (the newest wins)."""
        with self._cv:
            if self._pending is None or revision.number >= self._pending.number:
                self._pending = revision
            self._arrivals = [self._arrivals[-1], time.monotonic()]
            self._cv.notify_all()

    def report_error(self, message: str) -> None:
        """An error found outside the engine (a layer saved on disk that cannot be
        read): ``last_error`` until the next result is written."""
        with self._cv:
            self.error = message

    def stop(self, timeout: float | None = None) -> None:
        """Stop refining, write the final result (with pictures) and end the thread."""
        with self._cv:
            self._stopping = True
            self._cv.notify_all()
        self._thread.join(timeout)

    def _interrupted(self) -> bool:
        return self._stopping or self._pending is not None

    def _superseded(self) -> None:
        """Raise :class:`_Superseded` where a revision waits: the current round's estimate
        would be replaced (an edit to trace) or left unread (a rescale, whose preview is
        the last one rescaled) before anyone reads it."""
        if self._pending is not None:
            raise _Superseded

    def _wake(self, _future) -> None:
        """A batch ended: the engine's thread, waiting for its round, looks again."""
        with self._cv:
            self._cv.notify_all()

    # -- the session's knobs ----------------------------------------------------------------

    def session_settings(self) -> dict[str, Any]:
        """The knobs a client may read and change: filter threshold, target error or
        photon budget, paused."""
        with self._cv:
            s = self.settings
            return {"threshold": s.threshold, "target_error": s.target_error,
                    "photons": s.photons, "paused": self.paused}

    def update_settings(self, changes: dict[str, Any]) -> dict[str, Any]:
        """Apply a client's changes (checked as the command line's are: a
        :class:`~lumitrace.run.settings.SettingsError` names a bad one, nothing changes).
        A new threshold re-filters the current map at once, without retracing; a new
        target or budget goes on refining (or stops) from the photons traced."""
        new, paused = with_knobs(self.settings, changes)
        knobs = bool(set(changes) - {"paused"})
        with self._cv:
            refilter = new.threshold != self.settings.threshold
            r = self.refinement
            if r is not None and knobs:
                r.retarget(new)  # first: a budget it refuses changes nothing
            self.settings = new
            if paused is not None:
                self.paused = paused
            if r is not None and knobs:
                if refilter and r.accumulator.photons:
                    r.reestimate()
                self.done = r.finished()
                if not self.done:
                    self._written_full = False
            self._cv.notify_all()
        self.events.publish("settings", **self.session_settings())
        return self.session_settings()

    def snapshot_key(self) -> tuple | None:
        """What a preview of the current refinement depends on: (revision, photons,
        threshold, iteration), None before the first round; cheap, unlike
        :meth:`snapshot`."""
        with self._cv:
            r, rev = self.refinement, self.revision
            if r is None or rev is None or not r.accumulator.photons:
                return None
            return (rev.number, r.accumulator.photons, self.settings.threshold, r.iteration)

    def preview_waits(self) -> bool:
        """Whether a preview made now would be replaced at once: a revision waits to be
        taken, or the engine is estimating the map of new counts (its preview follows)."""
        with self._cv:
            r = self.refinement
            return self._pending is not None or (
                r is not None and r.accumulator.photons > 0 and r.estimate_current() is None)

    def preview_basis(self) -> tuple | None:
        """(the revision, the counts' lineage, the lights' fluxes and colours, whether it
        is done) of the current refinement (:attr:`~lumitrace.film.accumulate.Accumulator.
        lineage`, ``light_state``): whether an earlier preview, rescaled, shows the
        current revision; cheap."""
        with self._cv:
            r, rev = self.refinement, self.revision
            if r is None or rev is None:
                return None
            return rev.number, r.accumulator.lineage, r.accumulator.light_state(), self.done

    def snapshot(self) -> dict[str, Any] | None:
        """The current refinement as the preview needs it: a frozen copy of its counts and
        estimate, its revision and photons (None before the first round)."""
        with self._cv:
            r, rev = self.refinement, self.revision
            if r is None or rev is None or not r.accumulator.photons:
                return None
            est = r.estimate_current()  # None while the engine estimates new counts
            return {"scene": r.scene, "accumulator": r.accumulator.snapshot(),
                    "estimate_": est, "revision": rev.number,
                    "photons": r.accumulator.photons, "iteration": r.iteration,
                    "threshold": self.settings.threshold, "seed": self.settings.seed,
                    "target": self.settings.convergence_target,
                    "converged": bool(est and est.meets(self.settings.convergence_target)),
                    "seconds": time.perf_counter() - self.started}

    # -- status ---------------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        with self._cv:
            r, rev = self.refinement, self.revision
            acc = r.accumulator if r is not None else None
            est = r.estimate if r is not None else None
            elapsed = max(time.perf_counter() - self.started, 1e-9)
            return {
                "traced_revision": rev.number if rev else None,
                "state": ("stopping" if self._stopping else "error" if self._halted else
                          "starting" if r is None else "done" if self.done else
                          "paused" if self.paused else "tracing"),
                "photons": acc.photons if acc else 0,
                "iterations": r.iteration if r else 0,
                "relative_error": defined(est.error) if est else None,
                "relative_error_bound": defined(est.error_bound) if est else None,
                **self._judged(r),
                "target_error": self.settings.convergence_target,
                "photons_per_second": (acc.photons / elapsed) if acc else 0.0,
                "written_revision": self.written.get("revision"),
                "written_photons": self.written.get("photons"),
                "written_pictures": self.written.get("pictures"),
                "last_error": self.error,
                "tracing_frame": [*self.frame.center, self.frame.scale] if self.frame else None,
                "records_bytes": (sum(x.nbytes for x in r.records)
                                  if r is not None and r.records is not None else 0),
            }

    # -- the thread -----------------------------------------------------------------------

    def _main(self) -> None:
        threads = max(1, int(self.settings.threads))
        with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="lumitrace-trace") \
                as pool:
            self._pool = pool
            while True:
                with self._cv:
                    while self._pending is None and not self._stopping and self._idle():
                        self._cv.wait(self._pictures_wait() or None)
                    if self._stopping:
                        break
                    if self._pending is not None and not self._rescale_only(self._pending):
                        self._settle_burst()
                    pending, self._pending = self._pending, None
                try:
                    self._step(pending, pool)
                except Exception as exc:  # the engine never dies: the revision is reported
                    self._failed(pending, exc)
        if not self._halted:
            self._final_write()
        self._writer.close()
        if self._cluster is not None:
            self._cluster.close()

    def _idle(self) -> bool:
        """Nothing to do until a new revision: none traced yet, the current one done and
        written (its pictures drawn, or waiting for the edits to pause), or the current one
        failed."""
        return self._halted or self.paused or (self.refinement is None or self.done) \
            and not (self._pictures_due() and not self._pictures_wait())

    def _pictures_wait(self) -> float:
        """Seconds until the pictures of a done revision may be drawn: they wait until
        :data:`PICTURES_QUIET` s passed without a new revision, so an edit made while a
        designer is editing is not queued behind seconds of drawing (0: now)."""
        if not self._pictures_due():
            return 0.0
        return max(0.0, PICTURES_QUIET - (time.monotonic() - self._arrivals[1]))

    def _step(self, pending: Revision | None, pool: ThreadPoolExecutor) -> None:
        """One unit of work: take a new revision, draw the pictures, or trace a round."""
        if pending is not None:
            self._take(pending)
            self._halted = False
        elif self._pictures_due():
            if not self._pictures_wait():
                self._write(pictures=True, background=True)
        else:
            self._round(pool)

    def _failed(self, pending: Revision | None, exc: Exception) -> None:
        """A revision that cannot be traced or written: an ``error`` event and
        ``last_error``; the last result written stays served, nothing more is refined,
        and the next revision is traced afresh (the refinement may be half-changed)."""
        rev = pending or self.revision
        number = rev.number if rev is not None else None
        what = str(exc) if isinstance(exc, LumitraceError) else f"{type(exc).__name__}: {exc}"
        message = f"revision {number} cannot be traced: {what}"
        with self._cv:
            self._halted = True
            self.error = message
        self.events.publish("error", revision=number, message=message,
                            where=getattr(exc, "where", None))

    def _follows(self, rev: Revision) -> bool:
        """Whether ``rev`` comes right after the revision refined (its effect is then what
        changed since the scene traced)."""
        return self.revision is not None and rev.number == self.revision.number + 1

    def _rescale_only(self, rev: Revision) -> bool:
        """Whether ``rev`` follows the revision refined with a flux-only (or no) change: a
        rescale, taken at once, not held back to wait out a burst."""
        return (self.refinement is not None and not self._halted and self._follows(rev)
                and rev.effect.kind in ("none", "flux"))

    def _settle_burst(self) -> None:
        """In a burst of revisions, wait (holding the lock's condition) until it pauses."""
        start = time.monotonic()
        while (not self._stopping and self._arrivals[1] - self._arrivals[0] < BURST_GAP
               and time.monotonic() - start < BURST_WAIT):
            quiet = time.monotonic() - self._arrivals[1]
            if quiet >= BURST_QUIET:
                return
            self._cv.wait(BURST_QUIET - quiet)

    def _pictures_due(self) -> bool:
        """A done revision whose last write had no pictures (after a rescale, say), nor
        are they being drawn."""
        return self.refinement is not None and self.done and not self._written_full \
            and self._pictures_for != self.revision.number

    def _take(self, rev: Revision) -> None:
        """Start refining ``rev``: a rescale for a flux-only edit, the same photons for an
        edit the tracer does not see, a new refinement otherwise."""
        old = self.refinement if not self._halted else None  # after a failure: afresh
        kind = rev.effect.kind
        if old is not None and self.revision is not None and not self._follows(rev):
            # revisions were skipped (a burst): the edit is what changed since the scene
            # traced, not since the revision before (a material edit, then a flux edit)
            kind = max(kind, classify(old.scene, rev.scene).kind, key=EFFECT_KINDS.index)
        self.events.publish("revision", revision=rev.number, source=rev.source,
                            effect=rev.effect.as_dict(), layers=list(rev.layers))
        self._rescaled_at = -math.inf
        if old is not None and kind == "none":
            with self._cv:
                self.revision = rev
                old.scene = rev.scene
            if self.done:
                self._write(pictures=False)  # the pictures follow when nothing is pending
            return
        if old is not None and kind == "flux":
            self._rescaled_at = time.monotonic()
            with self._cv:
                old.rescale(rev.scene)
                self.revision = rev
                self._written_full = False  # this revision's pictures are still to come
            self._refreshed()
            # at once, in the background (the next flux edit need not wait for it); the
            # pictures follow if it is done
            self._write(pictures=False, background=True)
            return
        if old is not None and self.frame is not None:
            selection = select(old.records, old.scene, rev.scene, self.frame)
            traced = old.accumulator.photons
            if selection.restart is None and selection.photons > RETRACE_MAX_SHARE * traced:
                selection = Selection(restart=f"the edit can change {selection.photons:,} of "
                                              f"{traced:,} photons: a new trace shows a first "
                                              "result sooner (the map is the same)")
            if selection.restart is None:
                self._retrace(rev, selection)
                return
            self.events.publish("restart", revision=rev.number, reason=selection.restart)
            if selection.restart.startswith(("geometry moved outside", "the luminaire turned")):
                self.frame = None
        self.frame = self.frame or TracingFrame.of(rev.scene)
        refinement = Refinement(rev.scene, self.settings, FIRST_ROUND, self.records_cap,
                                self.frame.goniometer)
        t0 = time.perf_counter()
        self._prepared = prepare(rev.scene, self.frame)
        with self._cv:
            self.revision, self.refinement, self.done = rev, refinement, False
            self.started = t0
            self._written_full = False
            self._last_write = 0.0

    def _retrace(self, rev: Revision, selection) -> None:
        """Retrace the photons the edit can change; the rest stay (see
        :mod:`lumitrace.run.incremental`)."""
        r = self.refinement
        # no batch runs now: the edited parts' Embree geometries are rebuilt in place
        ps = prepare(rev.scene, self.frame, previous=self._prepared)

        def trace(work):
            return self._pool.map(lambda item: trace_batch(ps, item[0], photons=item[1],
                                                           records=True), work)
        with self._cv:
            try:
                done = retrace(r, rev.scene, selection, trace, self.settings.batch_size)
            except BaseException:
                if ps.embree is self._prepared.embree:  # the old revision's scene is gone
                    self._prepared = prepare(self.revision.scene, self.frame)
                raise
            self._prepared = ps
            self.revision = rev
            self.done = False
            self._written_full = False
        self.events.publish("retrace", revision=rev.number, photons=done.photons,
                            of=done.of, seconds=done.seconds,
                            rebuilt_parts=_rebuilt(ps, rev.scene))
        if r.records_dropped:
            self.events.publish("warning", revision=rev.number,
                                message="photon records dropped above their memory cap: "
                                        "the next edit restarts the trace")
        self._refreshed()
        self._write(pictures=False)

    def _rescales_first(self) -> None:
        """Wait while a rescale's files are written in the background (beside a round's
        tracing or estimate they take twice as long) and until :data:`RESCALE_QUIET` s
        after the last rescale, taking the rescales that come meanwhile; an edit to trace,
        or the engine's stop, ends the wait."""
        while True:
            self._writer.wait_cheap(lambda: self._stopping or self._pending is not None)
            rescale = self._pop_rescale()
            if rescale is not None:
                self._take(rescale)
                continue
            with self._cv:
                left = RESCALE_QUIET - (time.monotonic() - self._rescaled_at)
                if left <= 0 or self._pending is not None or self._stopping:
                    return
                self._cv.wait(left)

    def _round(self, pool: ThreadPoolExecutor) -> None:
        self._rescales_first()
        if self._interrupted():
            return
        r, ps = self.refinement, self._prepared
        jobs = r.next_jobs()
        if not jobs:
            self._finish()
            return
        keep = r.records is not None
        if self._cluster is not None:
            self._cluster.use(r.scene, self.frame)
            tallies = self._cluster(jobs, keep, self._interrupted)
            if tallies is None:
                return  # the round is dropped: its photons never reach the map
        else:
            futures = [pool.submit(trace_batch, ps, job, records=keep) for job in jobs]
            try:
                # the engine's condition wakes at a batch's end as at a new revision: an
                # edit waits for the running batches alone, not for the round
                for f in futures:
                    f.add_done_callback(self._wake)
                while (rescale := self._await(futures)) is not None:
                    # a flux edit is taken while the batches run, and the round kept: they
                    # count photons, which do not depend on the lights' flux
                    self._take(rescale)
                if self._interrupted():
                    _drain(futures)
                    return  # the round is dropped: its photons never reach the map
                tallies = [f.result() for f in futures]  # a failed batch raises here
            except BaseException:
                _drain(futures)  # a batch failed: none of the round may outlive it
                raise
        with self._cv:
            r.add_counts(tallies)
        # the estimate outside the lock (this thread alone changes the counts): a preview
        # or status request need not wait for it. An edit that came meanwhile abandons it
        # (the client waits for that edit's preview) and this round's counts stay without
        # their estimate until the next round's
        self._rescales_first()  # a flux edit taken while the round ran: its files first
        try:
            est = r.settle(checkpoint=self._superseded)
        except _Superseded:
            return
        acc = r.accumulator
        elapsed = time.perf_counter() - self.started
        self.events.publish("iteration", revision=self.revision.number,
                            iteration=r.iteration, photons=acc.photons,
                            relative_error=defined(est.error), seconds=elapsed,
                            photons_per_second=acc.photons / max(elapsed, 1e-9))
        if r.iteration == 1:  # a new trace's first map: its preview before its files
            self._refreshed()
        if self._reached():
            self._finish()
        elif self._pending is None and (  # a newer revision's files would replace these
                r.iteration <= EAGER_WRITES or
                time.perf_counter() - self._last_write >= WRITE_INTERVAL):
            self._write(pictures=False)

    def _await(self, futures) -> Revision | None:
        """Wait until the round's batches are done, one failed or the engine is
        interrupted; a rescale that comes ends it and is handed back (:meth:`_pop_rescale`)."""
        with self._cv:
            while not (self._interrupted() or all(f.done() for f in futures)
                       or any(f.done() and f.exception() for f in futures)):
                self._cv.wait()
        return self._pop_rescale()

    def _pop_rescale(self) -> Revision | None:
        """The pending revision, no longer pending, where it is a rescale
        (:meth:`_rescale_only`); else None."""
        with self._cv:
            rev = self._pending
            if rev is None or self._stopping or not self._rescale_only(rev):
                return None
            self._pending = None
            return rev

    @staticmethod
    def _judged(r) -> dict[str, Any]:
        """What the target is judged on, the judged error and whether it is met."""
        if r is None or not r.accumulator.photons:
            return {"target_of": None, "judged_error": None, "converged": False}
        on, error, converged = r.judged()
        return {"target_of": on, "judged_error": defined(error), "converged": converged}

    def _reached(self) -> bool:
        return self.refinement.finished()

    def _finish(self) -> None:
        with self._cv:
            self.done = True
        est = self.refinement.estimate
        self.events.publish("done", revision=self.revision.number,
                            photons=self.refinement.accumulator.photons,
                            relative_error=defined(est.error) if est else None,
                            relative_error_bound=defined(est.error_bound) if est else None,
                            **self._judged(self.refinement))
        unreached = self.refinement.accumulator.unreached_parts()
        if unreached:
            self.events.publish("warning", revision=self.revision.number,
                                message=f"{len(unreached)} part(s) no traced photon "
                                        f"reached: {', '.join(unreached[:10])}",
                                parts=unreached)
        if self._pending is None:
            self._refreshed()  # the final map's preview, ready (and a flux edit's to rescale)
            # the pictures now if the edits have paused, else after they do, and the files
            # then in the background (no round follows): a designer's next edit does not
            # wait behind them
            self._write(pictures=not self._pictures_wait(), background=True)

    def _final_write(self) -> None:
        self._writer.flush()  # pictures being drawn may be this revision's
        if self.refinement is not None and self.refinement.accumulator.photons and \
                not self._written_full:
            self._write(pictures=True)

    def _refreshed(self) -> None:
        """Tell the live view an edit's map is ready (its failure is its own: logged as an
        event, the engine goes on)."""
        if self.refreshed is not None:
            try:
                self.refreshed()
            except Exception as exc:  # the preview is the page's business, not the run's
                self.events.publish("warning", revision=self.revision.number,
                                    message=f"the preview could not be made: {exc}")

    def _write(self, pictures: bool, background: bool = False) -> None:
        """Publish the current refinement's result, here (after what the writer thread
        holds), or in the ``background``: by the writer, from a copy of the counts, while
        the engine goes on. Only a rescale's files and a done revision's files and pictures
        go to the background (an edit made while they are drawn is taken at once): beside a
        refinement's rounds, a background write slows them more than it saves."""
        r, rev = self.refinement, self.revision
        if r is None or not r.accumulator.photons:
            return
        seconds = time.perf_counter() - self.started
        self._last_write = time.perf_counter()
        if not background:
            result = r.result(seconds)
            self._writer.flush()
            self._publish(result, rev, pictures=pictures)
            return
        # a copy of the counts, its map estimated by the writer where it must be (after a
        # rescale, say): the engine is free for the next edit at once
        copy = r.result(seconds, frozen=True)
        if pictures:
            with self._cv:
                self._pictures_for = rev.number
        self._writer.put(lambda: self._publish(copy.estimated(), rev, pictures,
                                               abandon=pictures), cheap=not pictures)

    def _write_failed(self, exc: Exception) -> None:
        """A write on the writer thread that failed other than by a LumitraceError."""
        message = f"the result could not be written: {type(exc).__name__}: {exc}"
        with self._cv:
            self.error = message
        self.events.publish("error", message=message)

    def _publish(self, result, rev: Revision, pictures: bool, abandon: bool = False) -> None:
        """Write ``result`` of ``rev`` (one transaction, on the USD thread), and say so;
        ``abandon``: give the pictures up, the old set left, if a newer revision comes
        before they are all drawn (they follow once the edits pause again)."""

        def checkpoint() -> None:
            if abandon and (self._pending is not None or self.revision is not rev):
                raise _Superseded
        extra = {"revision": rev.number, "tracingFrame": [*self.frame.center, self.frame.scale]}
        t0 = time.perf_counter()
        try:
            record = write_outputs(result, self.out_dir, pictures=pictures, extra=extra,
                                   sublayer=self.sublayer,
                                   deliverables=pictures and self.deliverables,
                                   on_stage=lambda step: self.live.call(self.live.write, step),
                                   checkpoint=checkpoint)
        except _Superseded:
            with self._cv:
                self._drawn(rev, pictures)
            return
        except LumitraceError as exc:
            with self._cv:
                if pictures and rev is self.revision:
                    self._written_full = True  # not retried in a loop: the next revision will
                self._drawn(rev, pictures)
            self.error = str(exc)
            self.events.publish("error", revision=rev.number, message=str(exc))
            return
        now = time.perf_counter()
        with self._cv:
            self.record = record
            if rev is self.revision:  # not a revision the engine has since left
                self._written_full = pictures
            self._drawn(rev, pictures)
            self.written = {"revision": rev.number, "photons": result.accumulator.photons,
                            "pictures": pictures, "input_hash": record["input_hash"]}
            self.error = None
            self._cv.notify_all()  # the engine's thread looks again at what is due
        self.events.publish("written", revision=rev.number,
                            photons=result.accumulator.photons,
                            relative_error=record["relative_error"], pictures=pictures,
                            input_hash=record["input_hash"], seconds=now - t0,
                            outputs=record.summary().get("outputs", {}))

    def _drawn(self, rev: Revision, pictures: bool) -> None:
        """A write of ``rev`` ended: its pictures are no longer being drawn (under the
        lock)."""
        if pictures and self._pictures_for == rev.number:
            self._pictures_for = None
            self._cv.notify_all()


class _Superseded(Exception):
    """A newer revision came while a done revision's pictures were being drawn, or while
    a round's map was being estimated."""


def _drain(futures) -> None:
    """Cancel the batches not started and let the running ones end (before the scene
    they trace changes)."""
    for g in futures:
        g.cancel()
    for g in futures:
        if not g.cancelled():
            g.exception()


def _rebuilt(ps, scene) -> list[str] | None:
    """The parts whose Embree geometry the last preparation rebuilt (None: embreex, which
    rebuilds every part)."""
    rebuilt = getattr(ps.embree, "rebuilt", None)
    return None if rebuilt is None else [scene.parts[g] for g in rebuilt]
