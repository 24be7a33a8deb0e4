"""The engine in process: a done revision's pictures are drawn by the writer, so an edit
made while they are drawn is traced at once (its preview does not wait behind them); the
old revision's are given up at the next picture (its set left as it was), and the edit
gets pictures of its own, not those of the revision it replaced. The slow picture is held
by an event the test lets go, so what comes first is an order of events, never a time."""
from __future__ import annotations

import threading
import time

from lumitrace.publish import photometric
from lumitrace.serve import engine as engine_module
from helpers.engine import REFLECTOR, running_engine, set_delta

#: Longest wait for anything (a bound on a failure, not a speed).
WAIT_S = 120.0


def test_an_edit_made_while_the_pictures_are_drawn_is_previewed_at_once(tmp_path,
                                                                        monkeypatch):
    monkeypatch.setattr(engine_module, "PICTURES_QUIET", 0.0)  # pictures as soon as done
    drawing, release, drawn = threading.Event(), threading.Event(), []
    real = photometric.polar_diagram

    def slow_polar(path, *args, **kwargs):  # a slow picture, held until let go
        drawing.set()
        assert release.wait(WAIT_S)
        drawn.append(path)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(photometric, "polar_diagram", slow_polar)
    solids = []
    real_solid = photometric.photometric_solid
    monkeypatch.setattr(photometric, "photometric_solid",
                        lambda path, *a, **k: solids.append(path) or real_solid(path, *a, **k))
    previews = []
    with running_engine(tmp_path, refreshed=lambda: previews.append(time.monotonic())) as (live, eng):
        try:
            assert drawing.wait(WAIT_S), eng.status()  # revision 0 done, its pictures held
            assert eng.status()["traced_revision"] == 0
            edit = live.call(live.apply, set_delta(REFLECTOR, "lumitrace:specularReflectance",
                                                   0.5))
            before = len(previews)
            eng.submit(edit)
            deadline = time.monotonic() + WAIT_S
            # revision 1 previewed while revision 0's picture is still held: not behind it
            while not (len(previews) > before and eng.status()["traced_revision"] == 1):
                assert time.monotonic() < deadline, eng.status()
                time.sleep(0.005)
            assert drawn == [] and not release.is_set()
        finally:
            release.set()
        # revision 1's own pictures follow (the slow picture twice: 0's, then 1's)
        deadline = time.monotonic() + WAIT_S
        while not (len(drawn) == 2 and eng.status()["written_revision"] == 1
                   and eng.status()["written_pictures"]):
            assert time.monotonic() < deadline, (eng.status(), drawn)
            time.sleep(0.02)
        assert len(solids) == 1  # revision 0's write given up after its polar curve


def test_a_renderers_solid_given_up_by_an_edit_never_lands_and_the_renderer_goes_on(
        tmp_path, monkeypatch):
    """With a renderer process (a service at a terminal): revision 0's solid, handed to the
    renderer before its polar curve, is given up when the edit comes; the renderer is not
    stopped for it, draws revision 1's solid, and that is the one in the set (none drawn
    in this process, and no picture left in the renderer's folder)."""
    import pytest

    pytest.importorskip("pyvista")
    from lumitrace.photometry import solid_render

    monkeypatch.setenv("LUMITRACE_RENDERER", "process")
    renderer = solid_render.start_renderer()
    if renderer is None:
        pytest.skip("no renderer on one core")
    try:
        monkeypatch.setattr(engine_module, "PICTURES_QUIET", 0.0)
        drawing, edited, submitted = threading.Event(), threading.Event(), []
        real_polar, real_submit = photometric.polar_diagram, photometric.submit_solid

        def slow_polar(path, *args, **kwargs):
            if len(submitted) == 1:  # revision 0's: held until the edit has come
                drawing.set()
                assert edited.wait(WAIT_S)
            return real_polar(path, *args, **kwargs)

        def submit(path, *args, **kwargs):
            job = real_submit(path, *args, **kwargs)
            submitted.append((path, job))
            return job

        def no_vtk_here(*_):
            raise AssertionError("a solid drawn in the service's process")

        monkeypatch.setattr(photometric, "polar_diagram", slow_polar)
        monkeypatch.setattr(photometric, "submit_solid", submit)
        monkeypatch.setattr(solid_render, "draw_solid", no_vtk_here)
        with running_engine(tmp_path) as (live, eng):
            try:
                assert drawing.wait(WAIT_S), eng.status()
                edit = live.call(live.apply, set_delta(
                    REFLECTOR, "lumitrace:specularReflectance", 0.5))
                eng.submit(edit)
            finally:
                edited.set()
            deadline = time.monotonic() + 120
            while not (eng.status()["written_revision"] == 1
                       and eng.status()["written_pictures"]):
                assert time.monotonic() < deadline, eng.status()
                time.sleep(0.02)
        assert len(submitted) == 2 and all(job is not None for _, job in submitted)
        assert {job[0] for _, job in submitted} == {renderer}  # one renderer throughout
        assert renderer.alive()
        staged = submitted[1][0]  # in the set's staging folder, then published beside it
        solid = staged.parent.parent / staged.name
        assert solid.exists() and solid.stat().st_size > 10_000
        assert not list(renderer.folder.iterdir())
    finally:
        solid_render.stop_renderer()
