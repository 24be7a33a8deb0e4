"""The engine in process: a revision taken after skipped ones (a burst) is judged against
the scene traced, not the revision before it; a flux edit's preview is the last preview
rescaled, equal to one made afresh from the rescaled counts."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from lumitrace.photometry.distribution import photometry_of
from lumitrace.photometry.quantities import scaled_figures
from lumitrace.run.session import run
from lumitrace.serve.engine import Engine
from lumitrace.serve.viewer import PreviewCache, preview_parts, read_frame
from helpers.engine import REFLECTOR, SETTINGS, running_engine, set_delta


@pytest.fixture
def engine(tmp_path):
    with running_engine(tmp_path) as running:
        yield running


def _done(eng: Engine, revision: int) -> None:
    deadline = time.monotonic() + 120
    while not (eng.status()["state"] == "done" and eng.status()["traced_revision"] == revision
               and eng.status()["written_revision"] == revision):
        assert time.monotonic() < deadline, eng.status()
        time.sleep(0.01)


def test_a_flux_edit_after_a_skipped_material_edit_is_traced_with_the_material(engine):
    """Revision 1 darkens the reflector, revision 2 changes the flux alone; the engine gets
    revision 2 only (revision 1 skipped, as in a burst): it must not rescale revision 0's
    counts, which know nothing of the darker reflector."""
    live, eng = engine
    _done(eng, 0)
    frame = eng.frame
    live.call(live.apply, set_delta(REFLECTOR, "lumitrace:specularReflectance", 0.1))
    second = live.call(live.apply, set_delta("/Luminaire/LED", "lumitrace:luminousFlux", 1500.0))
    assert second.effect.kind == "flux"
    eng.submit(second)
    _done(eng, 2)
    fresh = run(second.scene, SETTINGS, frame=frame).accumulator
    np.testing.assert_array_equal(eng.refinement.accumulator.counts(), fresh.counts())
    assert eng.refinement.accumulator.emitters[0].flux == 1500.0


def _same_preview(frame, fresh) -> None:
    """A frame (header, arrays) holds what a preview made afresh holds: its arrays to
    float32, every figure to 1e-9."""
    (header, arrays), (fresh_header, fresh_arrays) = frame, fresh
    for name, a in fresh_arrays.items():  # the frame's arrays are float32
        np.testing.assert_allclose(arrays[name], a, rtol=2e-7, atol=1e-9 * a.max())
    for name, v in fresh_header["figures"].items():
        if name == "photometry_worst_at":
            continue  # cells of one relative error (near the pole) tie either way
        shown = header["figures"][name]
        if isinstance(v, float):
            assert shown == pytest.approx(v, rel=1e-9), name
        elif isinstance(v, (list, tuple)) and v and isinstance(v[0], float):
            assert shown == pytest.approx(list(v), rel=1e-9), name
        else:
            assert shown == (list(v) if isinstance(v, tuple) else v), name
    assert header["lamp_lumens"] == pytest.approx(fresh_header["lamp_lumens"], rel=1e-12)
    assert header["photons"] == fresh_header["photons"]


def test_a_flux_edits_first_preview_is_an_earlier_one_rescaled(tmp_path):
    """A flux edit after more rounds than the last preview saw: its first frame is the last
    one rescaled, of the photons that one had (what a preview of the new revision at those
    photons holds), and the current photons' frame follows."""
    previews, first = PreviewCache(), []

    def refreshed():  # the first round's preview, then none: the cache falls behind
        if not first:
            first.append(eng.snapshot())
            previews.get(eng)
    with running_engine(tmp_path, refreshed) as (live, eng):
        _first_preview_rescaled(live, eng, previews, first)


def _first_preview_rescaled(live, eng, previews, first) -> None:
    _done(eng, 0)
    early = first[0]
    assert early["photons"] < eng.refinement.accumulator.photons
    rev = live.call(live.apply, set_delta("/Luminaire/LED", "lumitrace:luminousFlux", 1500.0))
    eng.submit(rev)
    _done(eng, 1)
    header, arrays = read_frame(previews.get(eng))
    assert header["revision"] == 1 and header["photons"] == early["photons"]
    early["accumulator"].rescale(0, 1500.0)
    _same_preview((header, arrays), preview_parts(**{**early, "scene": rev.scene,
                                                     "estimate_": None, "revision": 1}))
    header, _ = read_frame(previews.get(eng))  # then the frame of the photons now
    assert (header["revision"], header["photons"]) == (1, eng.refinement.accumulator.photons)
    # a retrace takes photons out: no earlier frame stands for the edited revision
    material = live.call(live.apply, set_delta(REFLECTOR, "lumitrace:specularReflectance", 0.5))
    eng.submit(material)
    _done(eng, 2)
    assert read_frame(previews.get(eng))[0]["photons"] == eng.refinement.accumulator.photons


def test_a_flux_edits_preview_is_the_last_one_rescaled(engine):
    live, eng = engine
    _done(eng, 0)
    previews = PreviewCache()
    eng.refreshed = lambda: previews.get(eng)
    before = read_frame(previews.get(eng))
    rev = live.call(live.apply, set_delta("/Luminaire/LED", "lumitrace:luminousFlux", 1500.0))
    eng.submit(rev)
    _done(eng, 1)
    header, arrays = read_frame(previews.get(eng))
    assert header["revision"] == 1 and header["photons"] == before[0]["photons"]
    k = 1500.0 / 1200.0
    # what a preview made afresh from the rescaled counts holds
    _same_preview((header, arrays), preview_parts(**eng.snapshot()))
    for name, a in arrays.items():
        np.testing.assert_allclose(a, before[1][name] * k, rtol=2e-7)
    # the files are written from an estimate made afresh, not the rescaled one (their
    # photometry is the session seed's)
    ph = photometry_of(rev.scene, eng.refinement.accumulator, SETTINGS.seed)
    assert eng.record.summary()["photometry"]["peak_intensity"] == \
        ph.figures.peak_intensity
    assert scaled_figures({"peak_intensity": 2.0, "beam_angle_c0_c180": 3.0}, 2.0) == \
        {"peak_intensity": 4.0, "beam_angle_c0_c180": 3.0}


def test_a_previews_opening_and_ugr_are_the_files_of_the_sessions_seed(engine):
    """The preview measures the luminous opening (hence UGR and luminance) with the
    session's seed, as the files do: whichever of the two measured the counts last, the
    preview shows the same UGR (the opening of seed 0 is another one)."""
    from lumitrace.photometry import distribution
    from lumitrace.serve.viewer import UGR_KEYS, catalogue_ugr

    live, eng = engine
    _done(eng, 0)
    snap = eng.snapshot()
    distribution._LAST.clear()  # nothing measured: the preview measures afresh
    header, _ = read_frame(PreviewCache().get(eng))
    files = photometry_of(snap["scene"], snap["accumulator"], SETTINGS.seed)
    other = photometry_of(snap["scene"], snap["accumulator"], SETTINGS.seed + 1)
    want, unlike = catalogue_ugr(files), catalogue_ugr(other)
    for key in UGR_KEYS:
        assert header["figures"][key] == pytest.approx(want[key], rel=1e-12), key
    assert want[UGR_KEYS[0]] != unlike[UGR_KEYS[0]]  # the seed matters


def test_the_writer_writes_the_newest_and_a_flush_waits_for_it():
    """Background writes: one not begun when a newer one comes is dropped, a flush returns
    once the newest is written, and a failing write is reported, not fatal."""
    import threading

    from lumitrace.serve.writer import Writer

    done, failures, started = [], [], threading.Event()
    release = threading.Event()

    def job(name, wait=False):
        def run():
            started.set()
            if wait:
                release.wait(10)
            if name == "bad":
                raise OSError("disk full")
            done.append(name)
        return run

    writer = Writer(failures.append)
    writer.put(job("first", wait=True))
    assert started.wait(10)
    for name in ("second", "bad", "third"):  # while the first is written
        writer.put(job(name))
    release.set()
    writer.flush()
    assert done == ["first", "third"] and failures == []
    writer.put(job("bad"))
    writer.close()
    assert len(failures) == 1 and isinstance(failures[0], OSError)


def test_a_flux_edit_is_taken_while_a_round_runs_and_the_round_is_kept(tmp_path,
                                                                       monkeypatch):
    """The first round's batches are held until the flux edit is taken: the engine takes
    it while they run (a batch counts photons, whatever the lights' flux), keeps the round
    (no photon is traced twice) and ends with a fresh trace's counts."""
    import lumitrace.serve.engine as engine_module

    held, running, traced = threading.Event(), [], []
    original = engine_module.trace_batch

    def trace_batch(ps, job, **kw):
        running.append(job)
        assert held.wait(60)
        traced.append((job.emitter, job.first, job.count))
        return original(ps, job, **kw)

    monkeypatch.setattr(engine_module, "trace_batch", trace_batch)
    with running_engine(tmp_path) as (live, eng):
        try:
            _taken_while_held(live, eng, held, running, traced)
        finally:
            held.set()


def _taken_while_held(live, eng, held, running, traced) -> None:
    deadline = time.monotonic() + 60
    while not running:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    rev = live.call(live.apply, set_delta("/Luminaire/LED", "lumitrace:luminousFlux", 1500.0))
    eng.submit(rev)
    while eng.status()["traced_revision"] != 1:  # taken, the batches still held
        assert time.monotonic() < deadline
        time.sleep(0.005)
    assert eng.refinement.accumulator.photons == 0 and not traced
    held.set()
    _done(eng, 1)
    fresh = run(rev.scene, SETTINGS, frame=eng.frame).accumulator
    np.testing.assert_array_equal(eng.refinement.accumulator.counts(), fresh.counts())
    assert eng.refinement.accumulator.emitters[0].flux == 1500.0
    assert len(set(traced)) == len(traced) and \
        sum(n for _, _, n in traced) == fresh.photons  # the round kept, none again
