"""The photometric solid's picture drawn by VTK (pyvista), here or in a renderer process
started ahead of the run, so that loading VTK and rendering overlap the tracing, the files
and the polar curve on another core.

Loading pyvista and VTK costs a run that writes pictures about a second, and a solid drawn
in a new window 0.4-0.5 s more, all while the interpreter is held. A command that will
draw starts a renderer (:func:`start_renderer`) before it loads lumitrace (a service, as
it starts), forked from its own process once matplotlib's pyplot is loaded (which both
then share: the command draws the polar curve with it, pyvista loads most of matplotlib).
The renderer loads VTK while the photons are traced, opens one window (a service's warmed
up with a small solid), then draws each solid it is sent in that window (a window that has
drawn before draws the next in half the time) into a folder of its own, and the PNG is put
in its place when it is waited for: a picture no longer wanted (an edit came, a set was
rolled back) never lands, and the renderer goes on. Wherever it cannot (it did not start,
died, or failed a picture), the solid is drawn here, in a window of its own.

This module needs only the standard library, numpy and pyvista: the renderer loads it by
its file, without lumitrace and USD.
"""
from __future__ import annotations

import atexit
import contextlib
import importlib
import importlib.machinery
import os
import pickle
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
import types
from pathlib import Path

#: How long a drawing may take in the renderer before it is drawn here instead (s).
RENDER_TIMEOUT = 60.0


def _quiet_pyvista():
    """pyvista, offscreen, with VTK's messages off (no X server is not news)."""
    import pyvista as pv
    from vtkmodules.vtkCommonCore import vtkLogger, vtkObject  # (all of vtk: 0.5 s more)

    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_OFF)
    vtkObject.GlobalWarningDisplayOff()
    pv.OFF_SCREEN = True
    return pv


def draw_solid(path, pts, cd, tri, up_axis: str, title: str) -> Path:
    """Draw the solid (points ``pts`` (C, gamma, 3) coloured by ``cd`` (C, gamma), the
    luminaire's triangles ``tri`` (T, 3, 3)) with pyvista and write it to ``path`` (PNG):
    in the window this thread keeps (:func:`kept_window`), else in a window of its own."""
    keeping = getattr(_thread_windows, "keeping", False)
    canvas = getattr(_thread_windows, "canvas", None) if keeping else None
    if canvas is None:
        canvas = SolidCanvas()
    try:
        out = canvas.draw(path, pts, cd, tri, up_axis, title)
    except BaseException:  # a window in doubt is not drawn in again
        _thread_windows.canvas = None
        with contextlib.suppress(Exception):
            canvas.close()
        raise
    if keeping:
        _thread_windows.canvas = canvas
    else:
        canvas.close()
    return out


_thread_windows = threading.local()


@contextlib.contextmanager
def kept_window():
    """While in it, the solids this thread draws (:func:`draw_solid`) share one window, made
    at the first and closed at the end: a thread that draws one solid after another (a
    service's writer) draws each after the first in about half the time. An OpenGL context
    is current on one thread: the window stays with the thread that made it."""
    _thread_windows.keeping = True
    try:
        yield
    finally:
        _thread_windows.keeping = False
        canvas, _thread_windows.canvas = getattr(_thread_windows, "canvas", None), None
        if canvas is not None:
            with contextlib.suppress(Exception):
                canvas.close()


class SolidCanvas:
    """An offscreen window that draws photometric solids one after another. A new window
    spends 0.3-0.4 s of its first drawing setting up its OpenGL context and compiling its
    shaders (Mesa's software renderer); a window kept draws the next solid, its PNG
    included, in about 0.2 s, the same picture to the byte. The renderer keeps one
    (:func:`kept_window`; a service's warmed up as it starts)."""

    def __init__(self):
        self.pv = _quiet_pyvista()
        self.plotter = self.pv.Plotter(off_screen=True, window_size=(900, 800))

    def draw(self, path, pts, cd, tri, up_axis: str, title: str) -> Path:
        """Draw a solid as :func:`draw_solid` does, in place of the one before."""
        import numpy as np

        pv, plotter = self.pv, self.plotter
        plotter.suppress_rendering = True  # one rendering, of the whole scene, below
        try:
            plotter.clear_actors()
            for name in list(plotter.scalar_bars.keys()):  # (each keeps its last range)
                plotter.remove_scalar_bar(name, render=False)
            plotter.set_background("white")
            grid = pv.StructuredGrid(pts[..., 0], pts[..., 1], pts[..., 2])
            grid.point_data["cd"] = np.ascontiguousarray(cd).ravel(order="F")
            # false colour by intensity, with its candela scale
            plotter.add_mesh(grid, scalars="cd", cmap="inferno",
                             clim=(0.0, float(cd.max()) or 1.0), opacity=0.6,
                             smooth_shading=True, show_edges=True, edge_color="#777777",
                             line_width=0.2,
                             scalar_bar_args={"title": "intensity (cd)", "color": "black",
                                              "vertical": True, "position_x": 0.86,
                                              "position_y": 0.2, "height": 0.6,
                                              "width": 0.06, "fmt": "%.0f",
                                              "title_font_size": 16, "label_font_size": 14})
            if tri.size:
                faces = np.hstack([np.full((len(tri), 1), 3),
                                   np.arange(3 * len(tri)).reshape(-1, 3)])
                mesh = pv.PolyData(tri.reshape(-1, 3), faces.ravel())
                plotter.add_mesh(mesh, color="#7f8c8d", smooth_shading=False)
            if title:
                plotter.add_text(title, font_size=10, color="black")
            plotter.view_vector((1.0, -1.4, 0.8) if up_axis == "Z" else (1.0, 0.8, 1.4),
                                viewup=(0, 0, 1) if up_axis == "Z" else (0, 1, 0))
            plotter.add_axes(color="black")
        finally:
            plotter.suppress_rendering = False
        plotter.render()
        return _write_whole(path, plotter.screenshot)

    def close(self) -> None:
        self.plotter.close()


def _write_whole(path, write) -> Path:
    """Have ``write(name)`` write a file under a temporary name beside ``path``, then
    rename it to ``path``: a reader sees the old file or the whole new one."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=".tmp.png", dir=target.parent)
    os.close(fd)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # an ordinary file, as every output
        write(tmp)
        os.replace(tmp, target)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return target


# --- the renderer process -------------------------------------------------------------------

_BOOT = """import importlib.util, sys
spec = importlib.util.spec_from_file_location("_lumitrace_solid_render", sys.argv[1])
m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)
m.serve(warm_up=sys.argv[2:] == ["warm-up"])"""


def serve(warm_up: bool = False) -> None:
    """The renderer's loop: load VTK, say ``ready`` (with ``warm_up`` draw a first small
    solid, see :meth:`Renderer.__init__`), then draw each job, all in one window kept,
    read from standard input (a length and a pickle of ``(id, job file)``; the file, in
    the command's own folder for this renderer, a pickle of ``(path, pts, cd, tri,
    up_axis, title)``) and answer ``ok ID`` or ``error ID MESSAGE``, until standard input
    ends."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the command decides; its end ends this
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    out = sys.stdout
    try:
        load_renderer()  # the point: VTK loaded while the command traces
    except Exception as exc:  # noqa: BLE001  (the command draws it itself)
        out.write(f"unavailable {type(exc).__name__}\n")
        out.flush()
        return
    out.write("ready\n")
    out.flush()
    stdin = sys.stdin.buffer
    with kept_window():
        if warm_up and not select.select([stdin], [], [], 0)[0]:  # (a solid waiting: no)
            with contextlib.suppress(Exception):  # the first solid makes its own window
                _warm_up()
        while True:
            head = stdin.read(8)
            if len(head) < 8:
                return
            job = pickle.loads(stdin.read(struct.unpack("<Q", head)[0]))
            try:
                with open(job[1], "rb") as fh:
                    args = pickle.load(fh)
                os.unlink(job[1])
                draw_solid(*args)
                out.write(f"ok {job[0]}\n")
            except Exception as exc:  # noqa: BLE001
                out.write(f"error {job[0]} {type(exc).__name__}: "
                          f"{str(exc).splitlines()[0] if str(exc) else ''}\n")
            out.flush()


def load_renderer() -> None:
    """Load what drawing a solid needs: pyvista, VTK's window libraries, and pyvista's
    plotting, which a first Plotter would load, before the first solid, not after it
    came (matplotlib's pyplot, which pyvista imports but does not use, loaded when
    first used)."""
    _lean_matplotlib()
    _quiet_pyvista()
    import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (the window's libraries)
    import pyvista.plotting  # noqa: F401


def _warm_up() -> None:
    """Draw a small solid in this thread's kept window and throw it away: the window's
    context, its shaders and the PNG writer are then ready for the first real one."""
    import numpy as np

    c = np.radians(np.linspace(0.0, 360.0, 13))[:, None]
    g = np.radians(np.linspace(0.0, 180.0, 13))[None, :]
    r = np.maximum(np.cos(g), 0.0) + 0.0 * c
    pts = np.stack([r * np.sin(g) * np.cos(c), r * np.sin(g) * np.sin(c),
                    -r * np.cos(g)], axis=-1)
    tri = np.array([[[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]]], np.float32)
    with tempfile.TemporaryDirectory(prefix="lumitrace-warm-up-") as folder:
        draw_solid(Path(folder) / "warm-up.png", pts, 100.0 * r, tri, "Z", "warm-up")


def _lean_matplotlib() -> None:
    """The renderer's matplotlib: the Agg backend, no display looked for, the Artists'
    ``set()`` docstrings left short, as :mod:`lumitrace.pyplot` has them in a command's
    process (nobody reads them here), and pyplot, which pyvista imports at load but does
    not use to draw a solid, loaded only if a name of it is read."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    try:
        import matplotlib.artist as artist
    except ImportError:  # pyvista without matplotlib: nothing to spare
        return
    artist.kwdoc = lambda _artist: "(see the class's set_* methods)"
    if "matplotlib.pyplot" not in sys.modules:
        sys.modules["matplotlib.pyplot"] = _OnFirstUse("matplotlib.pyplot")


class _OnFirstUse(types.ModuleType):
    """A module that is loaded when one of its names is first read, not when imported.

    pyvista's colours import ``matplotlib.pyplot`` but read it only in a function the
    renderer never calls: deferred, the renderer is ready 0.61-0.87 s after its start, not
    0.70-1.00 s (medians 0.78 and 0.96 s, six starts each, in turn). On a first name read,
    the real module is loaded and its names become this module's."""

    def __init__(self, name: str):
        super().__init__(name)
        self.__spec__ = importlib.machinery.ModuleSpec(name, None)

    def __getattr__(self, attr: str):
        if attr.startswith("__"):
            raise AttributeError(attr)
        name = self.__name__
        if sys.modules.get(name) is self:
            del sys.modules[name]
        real = importlib.import_module(name)
        self.__dict__.update(real.__dict__)
        return getattr(real, attr)


class _Forked:
    """A renderer forked from this process, with what :class:`Renderer` uses of
    :class:`subprocess.Popen` (``pid``, ``stdin``, ``stdout``, ``poll``, ``wait``,
    ``kill``). The child has what this process loaded (numpy and matplotlib, which a new
    interpreter would load again); it runs :func:`serve` on two pipes and ends without
    this process's exit handlers. Forked from the main thread only, before the tracer's
    threads start: a fork copies one thread, and the child never calls USD or Embree,
    whose thread pools it does not have."""

    def __init__(self, warm_up: bool):
        for stream in (sys.stdout, sys.stderr):  # what is buffered is this process's
            with contextlib.suppress(Exception):
                stream.flush()
        jobs, self_jobs = os.pipe()
        answers_here, answers = os.pipe()
        try:
            pid = os.fork()
        except OSError:
            for fd in (jobs, self_jobs, answers_here, answers):
                os.close(fd)
            raise
        if pid == 0:  # pragma: no cover  (the child: coverage does not follow a fork)
            _forked_child(jobs, self_jobs, answers_here, answers, warm_up)
        os.close(jobs)
        os.close(answers)
        self.pid = pid
        self.returncode: int | None = None
        self.stdin = open(self_jobs, "wb")
        self.stdout = open(answers_here, "rb", buffering=0)

    def _reap(self, flags: int) -> None:
        """Its exit status, if it has ended (``flags``: 0 waits for it); one reaped
        elsewhere counts as ended normally."""
        try:
            pid, status = os.waitpid(self.pid, flags)
        except ChildProcessError:
            self.returncode = 0
            return
        if pid:
            self.returncode = os.waitstatus_to_exitcode(status)

    def poll(self) -> int | None:
        if self.returncode is None:
            self._reap(os.WNOHANG)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            if deadline is None:
                self._reap(0)
            elif time.monotonic() >= deadline:
                raise subprocess.TimeoutExpired("renderer", timeout)
            else:
                time.sleep(0.005)
        return self.returncode

    def kill(self) -> None:
        if self.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGKILL)


def _forked_child(jobs: int, self_jobs: int, answers_here: int, answers: int,
                  warm_up: bool) -> None:
    """The forked renderer: its jobs on standard input, its answers on standard output,
    nothing on standard error; ended by ``os._exit``, never returning to the code that
    forked it."""
    code = 1
    try:
        os.close(self_jobs)
        os.close(answers_here)
        null = os.open(os.devnull, os.O_RDWR)
        for fd, to in ((jobs, 0), (answers, 1), (null, 2)):
            os.dup2(fd, to)
            if fd > 2:
                os.close(fd)
        sys.stdin = open(0, "r", closefd=False)
        sys.stdout = open(1, "w", closefd=False)
        sys.stderr = open(2, "w", closefd=False)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        import faulthandler

        faulthandler.disable()  # a crash here is answered by drawing the solid there
        with contextlib.suppress(Exception):
            import ctypes

            ctypes.CDLL(None).prctl(15, b"lumitrace-solid")  # PR_SET_NAME, for ps and top
        serve(warm_up)
        code = 0
    finally:
        os._exit(code)


class Renderer:
    """A renderer process: started at once, used by :meth:`submit` and :meth:`wait`.

    It draws each picture into a folder of its own; :meth:`wait` puts the picture in its
    place. A picture no longer wanted (its set rolled back, a newer revision come) is just
    not waited for: it never reaches its place, and the renderer goes on to the next."""

    def __init__(self, warm_up: bool = False, fork: bool = False):
        """``warm_up``: draw a small solid as soon as VTK is loaded, so that the first real
        one is drawn in a window that has drawn before (0.2 s, not 0.4-0.5 s). That costs
        0.5 CPU s at once: a service, idle between edits, gains it back from its second
        solid on; a command tracing on every core would only be slowed by it (a 10M-photon
        run with pictures took 1.1 times as long with it, 6 runs in turn on 2 cores).
        ``fork``: forked from this process (:class:`_Forked`), not a new interpreter."""
        self.folder = Path(tempfile.mkdtemp(prefix="lumitrace-renderer-"))
        if fork:
            self.proc = _Forked(warm_up)
        else:
            self.proc = subprocess.Popen(
                [sys.executable, "-c", _BOOT, os.path.abspath(__file__)]
                + (["warm-up"] if warm_up else []), stdin=subprocess.PIPE,
                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, close_fds=True)
        self._ids = iter(range(1, 1 << 62))
        self._targets: dict[int, Path] = {}  # job -> where its picture goes once waited for
        #: whether it died of a signal while it drew (VTK crashed, most likely: drawing
        #: with VTK in the command's own process would take the command down with it)
        self.crashed = False
        self._lock = threading.Lock()
        self._buffer = b""

    def alive(self) -> bool:
        return self.proc.poll() is None

    def submit(self, path, pts, cd, tri, up_axis: str, title: str) -> int | None:
        """Send a solid to draw; its job id, or None when the renderer cannot take it.
        The solid's arrays (a megabyte or more) go into a file beside the pictures, and
        only its name through the pipe: a renderer still loading VTK does not read, and a
        pipe's 64 KB would hold the command until it did (a quarter of a second)."""
        with self._lock:
            if not self.alive():
                return None
            job = next(self._ids)
            spec = self.folder / f"{job}.job"
            try:
                with open(spec, "wb") as fh:
                    pickle.dump((str(self._drawn(job)), pts, cd, tri, up_axis, title), fh,
                                protocol=pickle.HIGHEST_PROTOCOL)
                data = pickle.dumps((job, str(spec)), protocol=pickle.HIGHEST_PROTOCOL)
                self.proc.stdin.write(struct.pack("<Q", len(data)) + data)
                self.proc.stdin.flush()
            except OSError:
                return None
            self._targets[job] = Path(path)
            return job

    def _drawn(self, job: int) -> Path:
        """Where the renderer writes job ``job``'s picture."""
        return self.folder / f"{job}.png"

    def _answered(self, job: int, ok: bool, wanted: bool) -> bool:
        """Job ``job`` answered: its picture put in its place if ``wanted`` and drawn
        (whether it was), removed from the renderer's folder either way."""
        drawn, target = self._drawn(job), self._targets.pop(job, None)
        try:
            if ok and wanted and target is not None:
                _write_whole(target, lambda tmp: shutil.copyfile(drawn, tmp))
                return True
            return False
        except OSError:
            return False
        finally:
            with contextlib.suppress(OSError):
                drawn.unlink()

    def wait(self, job: int, timeout: float = RENDER_TIMEOUT) -> bool:
        """Whether job ``job`` was drawn and written (answers to older jobs are passed
        over); False when it failed, the renderer ended or ``timeout`` seconds passed."""
        if self.proc.stdout.closed:  # ended by close(): nothing more will come
            return False
        deadline = time.monotonic() + timeout
        fd = self.proc.stdout.fileno()
        while True:
            while b"\n" in self._buffer:
                line, self._buffer = self._buffer.split(b"\n", 1)
                words = line.decode(errors="replace").split()
                if words[:1] in (["ok"], ["error"]) and len(words) > 1 and \
                        words[1].isdigit():
                    done = int(words[1])
                    placed = self._answered(done, words[0] == "ok", done == job)
                    if done == job:
                        return placed
                if words[:1] == ["unavailable"]:
                    return False
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                self.close()  # a renderer that hangs is not waited for again
                return False
            chunk = os.read(fd, 65536)
            if not chunk:  # it ended without an answer: killed by a signal is a crash
                self.crashed = (self.proc.wait() or 0) < 0
                if self.crashed:
                    _vtk_crashed.set()
                return False
            self._buffer += chunk

    def close(self) -> None:
        """End the renderer: its input closed (it ends when it has read it), then killed
        if it has not within a second."""
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        try:
            self.proc.stdout.close()
        except OSError:
            pass
        shutil.rmtree(self.folder, ignore_errors=True)


_renderer: Renderer | None = None
#: set once a renderer of this process died of a signal: VTK crashes here, so every later
#: solid of this process (a service draws many) is drawn with matplotlib
_vtk_crashed = threading.Event()


def vtk_crashed() -> bool:
    """Whether a renderer of this process died of a signal while it drew."""
    return _vtk_crashed.is_set()


def mode(fork: bool = False) -> str:
    """How this process's solids are drawn, as ``LUMITRACE_RENDERER`` says: ``fork`` (by a
    renderer forked from this process), ``process`` (by a renderer in an interpreter of its
    own) or ``inline`` (here). ``auto``, the default: forked where the caller may fork
    (``fork``: a ``trace`` or ``serve`` command, as it starts), else a renderer process
    for a process run at a terminal and here for others. Always ``inline`` on one core,
    where a process of its own only adds its start."""
    how = os.environ.get("LUMITRACE_RENDERER", "auto").lower()
    if how == "inline" or (os.cpu_count() or 1) < 2:
        return "inline"
    if how == "auto" and fork:
        how = "fork"
    elif how not in ("process", "fork"):
        how = "process" if _at_terminal() else "inline"
    return "process" if how == "fork" and not hasattr(os, "fork") else how


def _at_terminal() -> bool:
    """Whether this process's standard error is a terminal: a user waits for the run."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def start_renderer(warm_up: bool = False, fork: bool = False) -> Renderer | None:
    """Start this process's renderer where :func:`mode` asks for one (once; None where it is
    not, pyvista is not installed or the process cannot be started), to be used by the
    pictures this process draws; ``warm_up``: see :class:`Renderer`; ``fork``: the
    caller may fork (see :func:`mode`), which it does only from the main thread (another
    thread draws here), after loading pyplot where :mod:`lumitrace.pyplot` is loaded:
    both processes then share it (the command draws the polar curve with it, and pyvista
    loads most of matplotlib), and a run's pictures cost about the CPU of drawing them
    here, in two thirds of the time (``tools/startup.py``, a 1000-photon run, medians of
    seven: +1.22-1.25 CPU s, +0.76-0.77 s wall, against +1.07-1.16 CPU s, +1.02-1.10 s
    drawn here; a new interpreter's +1.34-1.50 CPU s)."""
    global _renderer
    if _renderer is not None and _renderer.alive():
        return _renderer
    import importlib.util

    how = mode(fork)
    if how == "inline" or importlib.util.find_spec("pyvista") is None:
        return None
    if how == "fork":
        if threading.current_thread() is not threading.main_thread():
            return None
        plots = sys.modules.get("lumitrace.pyplot")
        if plots is not None:
            plots.pyplot()
    try:
        _renderer = Renderer(warm_up, fork=how == "fork")
    except OSError:
        _renderer = None
        return None
    atexit.register(stop_renderer)
    return _renderer


def renderer() -> Renderer | None:
    """The renderer started in this process, if it still runs."""
    return _renderer if _renderer is not None and _renderer.alive() else None


def stop_renderer() -> None:
    """End this process's renderer, if one was started, at once: at the process's end
    every picture it was given and still wanted has been waited for."""
    global _renderer
    if _renderer is not None:
        _renderer.proc.kill()
        _renderer.close()
        _renderer = None
