"""Work nobody will read is given up: a round's map estimate when an edit to trace comes
during it, and a round's start while a rescale's files are written; what is handed to the
writer is a frozen copy of the counts whose map the writer estimates, equal to the
estimate made in place."""
from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest

from lumitrace.film.convergence import MapEstimate
from lumitrace.run.session import Refinement, run
from lumitrace.serve.writer import Writer
from lumitrace.stage.reader import read_stage
from lumitrace.trace.prepared import prepare
from lumitrace.trace.tracer import trace_batch
from helpers.engine import REFLECTOR, SETTINGS, running_engine, set_delta
from helpers.paths import ROOT


def _same_estimate(a: MapEstimate, b: MapEstimate) -> None:
    for field in dataclasses.fields(MapEstimate):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(y, np.ndarray):
            np.testing.assert_array_equal(x, y, err_msg=field.name)
        else:
            assert x == y or (x != x and y != y), field.name


@pytest.fixture(scope="module")
def refinement() -> Refinement:
    """The demo refined for two rounds, in this thread."""
    scene = read_stage(ROOT / "stages" / "downlight.usda")
    ps = prepare(scene)
    r = Refinement(scene, dataclasses.replace(SETTINGS, photons=1_000_000), 8192,
                   goniometer=ps.goniometer)
    for _ in range(2):
        r.add_round([trace_batch(ps, job) for job in r.next_jobs()])
    r.ps = ps
    return r


def test_an_abandoned_estimate_leaves_the_last_one_marked_stale(refinement):
    """A checkpoint that raises in the middle of :meth:`settle`: the estimate stays of the
    counts before (said so), the files' figures are dropped, and the next result estimates
    the counts afresh, equal to a settle left to finish."""
    r = refinement
    before = r.estimate
    r.add_counts([trace_batch(r.ps, job) for job in r.next_jobs()])
    calls = []

    def checkpoint():
        calls.append(1)
        if len(calls) == 2:  # after the whole map's filter, before the halves'
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        r.settle(checkpoint=checkpoint)
    assert r.estimate is before and r.estimate_current() is None and r.files is None
    fresh = r.result(1.0).estimate
    assert r.estimate_current() is fresh
    r.settle()
    _same_estimate(r.estimate, fresh)


def test_a_frozen_result_is_a_copy_estimated_where_it_is_written(refinement):
    """After a rescale the estimate is the last one scaled: a frozen result leaves the map
    to its writer (estimate None) and keeps its counts while more are added; estimated,
    its map equals the estimate made in place of the same counts, bit for bit."""
    r = refinement
    r.settle()
    scene = r.scene
    brighter = dataclasses.replace(scene, emitters=[
        dataclasses.replace(e, flux=1.5 * e.flux) for e in scene.emitters])
    r.rescale(brighter)
    frozen = r.result(2.0, frozen=True)
    assert frozen.estimate is None and frozen.photons == r.accumulator.photons
    counts = frozen.accumulator.counts().copy()
    in_place = r.result(2.0)
    r.add_counts([trace_batch(r.ps, job) for job in r.next_jobs()])  # the counts go on
    np.testing.assert_array_equal(frozen.accumulator.counts(), counts)
    assert r.accumulator.photons > frozen.photons
    _same_estimate(frozen.estimated().estimate, in_place.estimate)
    current = r.result(3.0, frozen=True)
    assert current.estimate is None  # the counts grew: not estimated yet
    r.settle()
    assert r.result(3.0, frozen=True).estimate is r.estimate  # current and exact: shared


def test_wait_cheap_waits_for_a_files_write_alone():
    """``wait_cheap`` returns once a cheap write is done, at once when told to stop or when
    what is written has pictures."""
    writer = Writer(lambda exc: None)
    release, started = threading.Event(), threading.Event()

    def held():
        started.set()
        release.wait(10)
    try:
        writer.put(held, cheap=True)
        assert started.wait(10)
        t = time.monotonic()
        writer.wait_cheap(lambda: True)
        assert time.monotonic() - t < 1.0  # told to stop
        threading.Timer(0.3, release.set).start()
        t = time.monotonic()
        writer.wait_cheap(lambda: False)
        assert 0.25 < time.monotonic() - t < 5.0 and release.is_set()
        release.clear()
        started.clear()
        writer.put(held)  # pictures: nothing to wait for
        assert started.wait(10)
        t = time.monotonic()
        writer.wait_cheap(lambda: False)
        assert time.monotonic() - t < 1.0
    finally:
        release.set()
        writer.close()


def test_an_edit_during_a_rounds_estimate_abandons_it(tmp_path, monkeypatch):
    """The engine's estimate of revision 0's first round is held in its first filter pass
    until a material edit is submitted: the estimate is given up at its next pass (no
    ``iteration`` event for that round), the edit is traced, and its counts equal a fresh
    trace's."""
    import lumitrace.film.convergence as convergence

    original, held, entered, passes = convergence.pull_push, threading.Event(), \
        threading.Event(), []

    def pull_push(*args, **kwargs):
        if threading.current_thread().name == "lumitrace-engine" and not held.is_set():
            passes.append(1)
            entered.set()
            assert held.wait(60)
        return original(*args, **kwargs)

    monkeypatch.setattr(convergence, "pull_push", pull_push)
    with running_engine(tmp_path) as (live, eng):
        try:
            assert entered.wait(60)
            rev = live.call(live.apply, set_delta(REFLECTOR, "lumitrace:specularReflectance",
                                                  0.5))
            eng.submit(rev)
        finally:
            held.set()
        deadline = time.monotonic() + 120
        while not (eng.status()["state"] == "done" and eng.status()["traced_revision"] == 1):
            assert time.monotonic() < deadline, eng.status()
            time.sleep(0.01)
        events = eng.events.since(0)
        assert len(passes) == 1
        assert not [e for e in events if e.kind == "iteration" and e.data["revision"] == 0]
        assert [e for e in events if e.kind == "iteration" and e.data["revision"] == 1]
        fresh = run(rev.scene, SETTINGS, frame=eng.frame).accumulator
        np.testing.assert_array_equal(eng.refinement.accumulator.counts(), fresh.counts())


def test_the_refinement_waits_out_a_run_of_flux_edits(tmp_path):
    """Flux edits sent mid-refinement, one every 50 ms: no round of a rescaled revision is
    estimated until :data:`RESCALE_QUIET` s after the last rescale before it (their
    previews and files are made without the tracing beside them), and the refinement then
    goes on."""
    from lumitrace.serve.engine import RESCALE_QUIET

    with running_engine(tmp_path) as (live, eng):
        deadline = time.monotonic() + 60
        eng.update_settings({"photons": 5_000_000})  # still tracing while the edits come
        while not eng.status()["iterations"]:
            assert time.monotonic() < deadline
            time.sleep(0.005)
        for k in range(4):
            rev = live.call(live.apply, set_delta("/Luminaire/LED", "lumitrace:luminousFlux",
                                                  1300.0 + 10.0 * k))
            assert rev.effect.kind == "flux"
            eng.submit(rev)
            time.sleep(0.05)
        while not (eng.status()["traced_revision"] == rev.number and
                   [e for e in eng.events.since(0)
                    if e.kind == "iteration" and e.data["revision"] == rev.number]):
            assert time.monotonic() < deadline, eng.status()
            time.sleep(0.01)
        events = eng.events.since(0)
        taken = [e.time for e in events if e.kind == "revision" and e.data["revision"] >= 1]
        assert len(taken) >= 2 and eng.status()["state"] == "tracing"
        # every round estimated after a rescale comes the quiet after the latest one before
        # it (a slow machine may space the edits further apart: the refinement then goes
        # on between them)
        rounds = [(e.time, max(t for t in taken if t <= e.time)) for e in events
                  if e.kind == "iteration" and e.data["revision"] >= 1]
        assert rounds and all(t >= last + RESCALE_QUIET - 0.01 for t, last in rounds), \
            [(round(t - last, 3)) for t, last in rounds]
