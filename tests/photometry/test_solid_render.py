"""The photometric solid drawn by a renderer process started ahead of the run: the same PNG
as drawn in the command's own process, a renderer that fails or dies costs only the drawing
here, an abandoned picture is never written, and the command leaves no renderer behind."""
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyvista")

from helpers.renderers import renderers  # noqa: E402
from lumitrace.photometry import solid_render  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module", params=["process", "fork"])
def _module_renderer(request):
    """Renderers for this module's tests, of each kind (a new interpreter, and forked from
    this process): one is shared until a test ends it (each start loads VTK again, a second
    of CPU that the suite's other worker feels)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("LUMITRACE_RENDERER", request.param)
        solid_render.stop_renderer()
        yield request.param
        solid_render.stop_renderer()


@pytest.fixture
def renderer(_module_renderer):
    """This process's renderer, running (started again where a test before ended it)."""
    r = solid_render.start_renderer()
    if r is None:
        pytest.skip("no renderer on this machine (one core)")
    assert isinstance(r.proc, solid_render._Forked) is (_module_renderer == "fork")
    return r


def _solid():
    """A small solid: a cosine lobe on a 10 x 8 grid around two triangles."""
    c = np.radians(np.linspace(0, 360, 10))[:, None]
    g = np.radians(np.linspace(0, 180, 8))[None, :]
    cd = 100.0 * np.clip(np.cos(g), 0, None) * np.ones_like(c)
    pts = np.stack([np.sin(g) * np.cos(c), np.sin(g) * np.sin(c), -np.cos(g) + 0 * c], -1)
    pts = pts * (cd / cd.max())[..., None]
    tri = np.array([[[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]],
                    [[0, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]], np.float64)
    return pts, cd, tri


def test_the_renderer_draws_the_png_this_process_draws(renderer, tmp_path):
    pts, cd, tri = _solid()
    job = renderer.submit(tmp_path / "there.png", pts, cd, tri, "Z", "a title")
    assert job is not None and renderer.wait(job)
    solid_render.draw_solid(tmp_path / "here.png", pts, cd, tri, "Z", "a title")
    there, here = (tmp_path / n for n in ("there.png", "here.png"))
    assert there.stat().st_size > 10_000
    assert there.read_bytes() == here.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["here.png", "there.png"]  # no temp


def test_the_renderer_loads_pyplot_only_when_a_name_of_it_is_read():
    code = """import sys
from lumitrace.photometry import solid_render
solid_render.load_renderer()
print('matplotlib.figure' in sys.modules)
import matplotlib.pyplot as plt
print('matplotlib.figure' in sys.modules)
fig = plt.figure()  # the first name read: the real pyplot, under its own name
import matplotlib.pyplot as again
print(type(fig).__name__, again.figure is plt.figure, sys.modules['matplotlib.pyplot'] is again,
      plt.rcParams is again.rcParams, 'matplotlib.figure' in sys.modules)"""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "service"))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120, check=True).stdout.split("\n")
    assert out[:3] == ["False", "False", "Figure True True True True"]


def test_solids_drawn_one_after_another_in_the_kept_window_are_each_the_fresh_picture(
        renderer, tmp_path):
    """The renderer draws in one window (warmed up, then reused): nothing of a solid drawn
    before (its scale, its camera, its title, its luminaire) is left in the next."""
    pts, cd, tri = _solid()
    solids = [(pts, cd, tri, "Z", "a title"),
              (2.0 * pts, 40.0 * cd, tri[:1], "Y", ""),  # a wider scale, no title, Y up
              (pts, cd, tri[:0], "Z", "again")]  # the first scale again, no luminaire
    jobs = [renderer.submit(tmp_path / f"there{i}.png", *s) for i, s in enumerate(solids)]
    assert all(job is not None for job in jobs)
    assert all(renderer.wait(job) for job in jobs)
    for i, s in enumerate(solids):
        solid_render.draw_solid(tmp_path / f"here{i}.png", *s)
        there = (tmp_path / f"there{i}.png").read_bytes()
        here = (tmp_path / f"here{i}.png").read_bytes()
        assert len(there) > 10_000 and there == here, f"solid {i} differs"
    # and the in-process canvas, kept, draws them alike
    canvas = solid_render.SolidCanvas()
    try:
        for i, s in enumerate(reversed(solids)):
            canvas.draw(tmp_path / f"kept{i}.png", *s)
            assert (tmp_path / f"kept{i}.png").read_bytes() == \
                (tmp_path / f"here{len(solids) - 1 - i}.png").read_bytes()
    finally:
        canvas.close()


def test_a_thread_keeping_its_window_draws_its_solids_in_one_and_closes_it(tmp_path,
                                                                          monkeypatch):
    """Without a renderer (a service started by a script), a thread inside
    :func:`kept_window` (the service's writer) draws its solids in one window, each the PNG
    a window of its own draws, and closes it at the end; elsewhere each gets its own."""
    made, closed = [], []

    class Counted(solid_render.SolidCanvas):
        def __init__(self):
            super().__init__()
            made.append(self)

        def close(self):
            closed.append(self)
            super().close()

    monkeypatch.setattr(solid_render, "SolidCanvas", Counted)
    pts, cd, tri = _solid()
    solids = [(pts, cd, tri, "Z", "one"), (2.0 * pts, 9.0 * cd, tri[:1], "Y", ""),
              (pts, cd, tri, "Z", "one")]

    inside = []

    def writer():
        with solid_render.kept_window():
            for i, s in enumerate(solids):
                solid_render.draw_solid(tmp_path / f"kept{i}.png", *s)
            inside.append((len(made), len(closed)))

    t = threading.Thread(target=writer)
    t.start()
    t.join()
    assert inside == [(1, 0)]  # one window, open until the end
    assert len(made) == 1 and closed == made
    for i, s in enumerate(solids):  # here, outside: a window each
        solid_render.draw_solid(tmp_path / f"own{i}.png", *s)
        assert (tmp_path / f"own{i}.png").read_bytes() == \
            (tmp_path / f"kept{i}.png").read_bytes(), f"solid {i} differs"
    assert len(made) == 1 + len(solids) and closed == made


def test_a_failed_picture_is_answered_and_the_renderer_goes_on(renderer, tmp_path):
    pts, cd, tri = _solid()
    bad = renderer.submit(tmp_path / "no such folder" / "x.png", pts, cd, tri, "Z", "")
    good = renderer.submit(tmp_path / "x.png", pts, cd, tri, "Y", "")
    assert not renderer.wait(bad)
    assert renderer.wait(good) and (tmp_path / "x.png").exists()


def test_a_crashed_renderer_costs_only_the_drawing_here(renderer, tmp_path, monkeypatch):
    """The solid of a real stage's grid: its renderer crashing (SIGSEGV) after the picture
    was handed over, the picture is drawn in this process all the same, and not with VTK,
    which would take the command down with it."""
    from lumitrace.photometry.diagrams import photometric_solid, submit_solid
    from lumitrace.photometry.distribution import photometry_of
    from lumitrace.run.session import run
    from lumitrace.run.settings import TraceSettings
    from lumitrace.stage.reader import read_stage

    scene = read_stage(ROOT / "stages" / "reference" / "mirror_cup.usda")
    result = run(scene, TraceSettings(photons=50_000, seed=1))
    grid = photometry_of(scene, result.accumulator).grid
    job = submit_solid(tmp_path / "solid.png", grid, scene, "cup")
    assert job is not None
    os.kill(renderer.proc.pid, signal.SIGSEGV)
    renderer.proc.wait()

    def no_vtk_here(*_):
        raise AssertionError("VTK drawn in the command's process after the renderer crashed")

    monkeypatch.setattr(solid_render, "draw_solid", no_vtk_here)
    monkeypatch.setattr(solid_render, "_vtk_crashed", threading.Event())  # this test's own
    photometric_solid(tmp_path / "solid.png", grid, scene, "cup", job)
    assert renderer.crashed
    assert (tmp_path / "solid.png").stat().st_size > 10_000
    assert solid_render.renderer() is None
    assert submit_solid(tmp_path / "again.png", grid, scene, "cup") is None
    # a process that draws many solids (a service) keeps away from VTK from then on
    photometric_solid(tmp_path / "again.png", grid, scene, "cup", None)
    assert (tmp_path / "again.png").stat().st_size > 10_000


def test_an_abandoned_picture_is_never_written(renderer, tmp_path):
    """A picture not waited for (its set rolled back) never reaches its place; the renderer
    draws the next one, and keeps no file of either."""
    pts, cd, tri = _solid()
    late = renderer.submit(tmp_path / "late.png", pts, cd, tri, "Z", "")
    job = renderer.submit(tmp_path / "next.png", pts, cd, tri, "Z", "")
    assert late is not None and job is not None
    assert renderer.wait(job)
    time.sleep(0.3)
    assert [p.name for p in tmp_path.iterdir()] == ["next.png"]
    assert renderer.alive() and not list(renderer.folder.iterdir())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="no renderer on one core")
@pytest.mark.parametrize("kind", ["process", "auto"])
def test_the_command_starts_a_renderer_at_once_and_leaves_none(tmp_path, kind):
    """The ``lumitrace`` entry point starts the renderer before lumitrace loads (seen while
    the run traces; by default forked), the solid it draws is written, and once the
    command has ended no renderer of it is left; a SIGTERM mid-run leaves none either."""
    stage = tmp_path / "cup.usda"
    stage.write_bytes((ROOT / "stages" / "reference" / "mirror_cup.usda").read_bytes())
    cmd = [sys.executable, "-c", "import sys, lumitrace_launch; sys.exit(lumitrace_launch.main())",
           "trace", str(stage), "--photons", "100000", "--no-progress", "--no-sublayer",
           "--out", str(tmp_path / "out")]
    env = dict(os.environ, LUMITRACE_RENDERER=kind)  # (stderr is not a terminal)
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=env)
    seen = set()
    for _ in range(100):
        seen = renderers(p.pid)
        if seen or p.poll() is not None:
            break
        time.sleep(0.02)
    out, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    assert seen, "no renderer started"
    assert (tmp_path / "out" / "cup.solid.png").stat().st_size > 10_000
    time.sleep(0.2)
    assert not (seen & renderers())
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=env)
    seen = set()
    for _ in range(100):
        seen = renderers(p.pid)
        if seen:
            break
        time.sleep(0.02)
    assert seen, "no renderer started"
    p.send_signal(signal.SIGTERM)
    p.communicate(timeout=120)
    for _ in range(50):  # the renderer ends with its command
        if not (seen & renderers()):
            break
        time.sleep(0.05)
    assert not (seen & renderers())


def test_by_default_a_trace_forks_its_renderer_and_a_service_follows_its_terminal(
        monkeypatch):
    """``auto``: a ``trace`` (which may fork) forks its renderer, at a terminal or not; a
    service gets a renderer process at a terminal and draws in its own process for a
    script; ``process``, ``fork`` and ``inline`` say it outright; one core draws here."""
    class Stream:
        def __init__(self, tty):
            self.tty = tty

        def isatty(self):
            return self.tty

    monkeypatch.setattr(solid_render.os, "cpu_count", lambda: 2)
    for how, tty, fork, want in (("auto", True, True, "fork"), ("auto", False, True, "fork"),
                                 ("auto", True, False, "process"),
                                 ("auto", False, False, "inline"),
                                 ("process", False, True, "process"),
                                 ("fork", True, False, "fork"),
                                 ("inline", True, True, "inline")):
        monkeypatch.setenv("LUMITRACE_RENDERER", how)
        monkeypatch.setattr(solid_render.sys, "stderr", Stream(tty))
        assert solid_render.mode(fork) == want, (how, tty, fork)
    monkeypatch.setattr(solid_render.os, "cpu_count", lambda: 1)
    for how in ("process", "fork", "auto"):
        monkeypatch.setenv("LUMITRACE_RENDERER", how)
        assert solid_render.mode(True) == "inline"


def test_a_renderer_is_forked_only_from_the_main_thread(monkeypatch):
    """Another thread of a process that may run others (a library's caller) draws here:
    a fork copies one thread and whatever the others hold."""
    monkeypatch.setenv("LUMITRACE_RENDERER", "fork")
    monkeypatch.setattr(solid_render, "_renderer", None)
    started = []
    t = threading.Thread(target=lambda: started.append(solid_render.start_renderer(fork=True)))
    t.start()
    t.join()
    assert started == [None] and solid_render.renderer() is None


def test_a_forked_renderer_reaped_elsewhere_is_not_waited_for_again(renderer, tmp_path):
    """A forked renderer whose end was collected by someone else (a handler of the
    caller's that waits for any child): waiting for its picture and closing it return,
    and the picture is drawn here."""
    if not isinstance(renderer.proc, solid_render._Forked):
        pytest.skip("a renderer process of its own is waited for by subprocess")
    pts, cd, tri = _solid()
    os.kill(renderer.proc.pid, signal.SIGKILL)
    os.waitpid(renderer.proc.pid, 0)
    job = renderer.submit(tmp_path / "x.png", pts, cd, tri, "Z", "")
    assert job is None or not renderer.wait(job, timeout=10)
    renderer.close()
    assert renderer.proc.returncode is not None and not renderer.alive()


FORKED = """
import atexit, os, sys
import numpy as np
from lumitrace.photometry import solid_render
atexit.register(lambda: print("exit handler", flush=True))
print("written before the fork", end="")  # still in this process's buffer at the fork
r = solid_render.start_renderer(fork=True)
assert isinstance(r.proc, solid_render._Forked), r
g = np.radians(np.linspace(0, 180, 8))[None, :] + 0 * np.radians(np.linspace(0, 360, 10))[:, None]
pts = np.stack([np.sin(g), 0 * g, -np.cos(g)], -1)
job = r.submit(sys.argv[1], pts, 10 * np.cos(g) + 10, np.zeros((0, 3, 3)), "Z", "")
assert r.wait(job), "not drawn"
with open(f"/proc/{r.proc.pid}/comm") as f:
    print(" |", f.read().strip(), "|", r.proc.pid != os.getpid())
solid_render.stop_renderer()
assert r.proc.returncode is not None
"""


@pytest.mark.skipif(not hasattr(os, "fork") or not sys.platform.startswith("linux"),
                    reason="forks; reads /proc")
@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="no renderer on one core")
def test_a_forked_renderer_leaves_the_process_s_output_and_exit_handlers_alone(tmp_path):
    """The forked child ends without this process's exit handlers and never writes what
    this process had buffered at the fork: each line below comes once, from here."""
    p = subprocess.run([sys.executable, "-c", FORKED, str(tmp_path / "solid.png")],
                       capture_output=True, text=True, timeout=120,
                       env=dict(os.environ, LUMITRACE_RENDERER="fork"))
    assert p.returncode == 0, p.stderr
    assert p.stdout == "written before the fork | lumitrace-solid | True\nexit handler\n"
    assert (tmp_path / "solid.png").stat().st_size > 10_000


def test_a_solid_handed_over_does_not_wait_for_the_renderer_to_read(tmp_path, monkeypatch):
    """A renderer still loading VTK reads nothing: a solid of a few megabytes handed to it
    must not hold the command until it does (a pipe holds 64 KB). Here a renderer that
    never reads at all: the submit returns, and its arrays wait in the renderer's folder."""
    monkeypatch.setattr(solid_render, "_BOOT", "import time; time.sleep(60)")
    r = solid_render.Renderer()
    try:
        g = np.linspace(0.0, 1.0, 400)
        pts = np.stack(np.meshgrid(g, g, g[:3], indexing="ij"), -1)[..., 0, :]  # 400 x 400
        cd = np.ones(pts.shape[:2])
        done = []
        t = threading.Thread(target=lambda: done.append(
            r.submit(tmp_path / "x.png", pts, cd, np.zeros((0, 3, 3)), "Z", "")), daemon=True)
        t.start()
        t.join(timeout=20)
        assert done and done[0] == 1, "the submit waited for the renderer to read"
        assert (r.folder / "1.job").stat().st_size > pts.nbytes
    finally:
        r.proc.kill()
        r.close()
    assert not r.folder.exists()
