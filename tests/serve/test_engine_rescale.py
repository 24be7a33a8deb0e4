"""The engine in process: a revision taken after skipped ones (a burst) is judged against
the scene traced, not the revision before it; a flux edit's preview is the last preview
rescaled, equal to one made afresh from the rescaled counts."""
from __future__ import annotations

import shutil
import time

import numpy as np
import pytest

from lumitrace.photometry.distribution import photometry_of
from lumitrace.photometry.quantities import scaled_figures
from lumitrace.run.session import run
from lumitrace.run.settings import TraceSettings
from lumitrace.serve.engine import Engine
from lumitrace.serve.events import EventLog
from lumitrace.serve.live import LiveStage
from lumitrace.serve.viewer import PreviewCache, preview_parts, read_frame
from helpers.paths import ROOT

REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
SETTINGS = TraceSettings(photons=40_000, resolution=16, threads=2, seed=5)


def _set(path: str, prop: str, value) -> list[dict]:
    return [{"op": "set", "path": path, "property": prop, "value": value}]


@pytest.fixture
def engine(tmp_path):
    shutil.copy(ROOT / "stages" / "downlight.usda", tmp_path / "downlight.usda")
    live = LiveStage(tmp_path / "downlight.usda")
    eng = Engine(live, SETTINGS, EventLog(first_id=1), tmp_path / "out")
    eng.start(live.start())
    yield live, eng
    eng.stop()
    live.close()


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
    live.call(live.apply, _set(REFLECTOR, "lumitrace:specularReflectance", 0.1))
    second = live.call(live.apply, _set("/Luminaire/LED", "lumitrace:luminousFlux", 1500.0))
    assert second.effect.kind == "flux"
    eng.submit(second)
    _done(eng, 2)
    fresh = run(second.scene, SETTINGS, frame=frame).accumulator
    np.testing.assert_array_equal(eng.refinement.accumulator.counts(), fresh.counts())
    assert eng.refinement.accumulator.emitters[0].flux == 1500.0


def test_a_flux_edits_preview_is_the_last_one_rescaled(engine):
    live, eng = engine
    _done(eng, 0)
    previews = PreviewCache()
    eng.refreshed = lambda: previews.get(eng)
    before = read_frame(previews.get(eng))
    rev = live.call(live.apply, _set("/Luminaire/LED", "lumitrace:luminousFlux", 1500.0))
    eng.submit(rev)
    _done(eng, 1)
    header, arrays = read_frame(previews.get(eng))
    assert header["revision"] == 1 and header["photons"] == before[0]["photons"]
    k = 1500.0 / 1200.0
    # what a preview made afresh from the rescaled counts holds
    fresh_header, fresh = preview_parts(**eng.snapshot())
    for name, a in fresh.items():  # the frame's arrays are float32
        np.testing.assert_allclose(arrays[name], a, rtol=2e-7, atol=1e-9 * a.max())
        np.testing.assert_allclose(arrays[name], before[1][name] * k, rtol=2e-7)
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
    # the files are written from an estimate made afresh, not the rescaled one
    ph = photometry_of(rev.scene, eng.refinement.accumulator)
    assert eng.record.summary()["photometry"]["peak_intensity"] == \
        ph.figures.peak_intensity
    assert scaled_figures({"peak_intensity": 2.0, "beam_angle_c0_c180": 3.0}, 2.0) == \
        {"peak_intensity": 4.0, "beam_angle_c0_c180": 3.0}


def test_the_writer_writes_the_newest_and_a_flush_waits_for_it():
    """Background writes: one not begun when a newer one comes is dropped, a flush returns
    once the newest is written, and a failing write is reported, not fatal."""
    import threading

    from lumitrace.serve.engine import _Writer

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

    writer = _Writer(failures.append)
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
