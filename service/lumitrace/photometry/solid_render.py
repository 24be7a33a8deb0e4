"""The photometric solid's picture drawn by VTK (pyvista), here or in a process of its own
started ahead of the run, so that loading VTK and rendering overlap the tracing, the files
and the polar curve on another core.

Loading pyvista and VTK and setting up an offscreen window cost a run that writes pictures
about 0.65 s before the solid's 0.35 s of drawing, all while the interpreter is held. A
command that will draw starts a renderer (:func:`start_renderer`) before it reads the
stage; the renderer loads VTK while the photons are traced, then draws each solid it is
sent and writes its PNG (whole, under another name, then renamed). Wherever it cannot
(it did not start, died, or failed a picture), the solid is drawn here, as before.

This module needs only the standard library, numpy and pyvista: the renderer loads it by
its file, without lumitrace and USD.
"""
from __future__ import annotations

import atexit
import os
import pickle
import select
import struct
import subprocess
import sys
import tempfile
import threading
import time
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
    luminaire's triangles ``tri`` (T, 3, 3)) with pyvista and write it to ``path`` (PNG)."""
    import numpy as np

    pv = _quiet_pyvista()
    grid = pv.StructuredGrid(pts[..., 0], pts[..., 1], pts[..., 2])
    grid.point_data["cd"] = np.ascontiguousarray(cd).ravel(order="F")
    plotter = pv.Plotter(off_screen=True, window_size=(900, 800))
    plotter.set_background("white")
    # false colour by intensity, with its candela scale
    plotter.add_mesh(grid, scalars="cd", cmap="inferno", clim=(0.0, float(cd.max()) or 1.0),
                     opacity=0.6, smooth_shading=True, show_edges=True, edge_color="#777777",
                     line_width=0.2,
                     scalar_bar_args={"title": "intensity (cd)", "color": "black",
                                      "vertical": True, "position_x": 0.86,
                                      "position_y": 0.2, "height": 0.6, "width": 0.06,
                                      "fmt": "%.0f", "title_font_size": 16,
                                      "label_font_size": 14})
    if tri.size:
        faces = np.hstack([np.full((len(tri), 1), 3), np.arange(3 * len(tri)).reshape(-1, 3)])
        mesh = pv.PolyData(tri.reshape(-1, 3), faces.ravel())
        plotter.add_mesh(mesh, color="#7f8c8d", smooth_shading=False)
    if title:
        plotter.add_text(title, font_size=10, color="black")
    plotter.view_vector((1.0, -1.4, 0.8) if up_axis == "Z" else (1.0, 0.8, 1.4),
                        viewup=(0, 0, 1) if up_axis == "Z" else (0, 1, 0))
    plotter.add_axes(color="black")
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=".tmp.png", dir=target.parent)
    os.close(fd)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # an ordinary file, as every output
        plotter.screenshot(tmp)
        os.replace(tmp, target)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    finally:
        plotter.close()
    return target


# --- the renderer process -------------------------------------------------------------------

_BOOT = """import importlib.util, sys
spec = importlib.util.spec_from_file_location("_lumitrace_solid_render", sys.argv[1])
m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m); m.serve()"""


def serve() -> None:
    """The renderer's loop: load VTK, say ``ready``, then draw each job read from standard
    input (a length and a pickle of ``(id, path, pts, cd, tri, up_axis, title)``) and
    answer ``ok ID`` or ``error ID MESSAGE``, until standard input ends."""
    import signal

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
        _quiet_pyvista()  # the point: VTK loaded while the command traces
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (the window's libraries)
    except Exception as exc:  # noqa: BLE001  (the command draws it itself)
        out.write(f"unavailable {type(exc).__name__}\n")
        out.flush()
        return
    out.write("ready\n")
    out.flush()
    stdin = sys.stdin.buffer
    while True:
        head = stdin.read(8)
        if len(head) < 8:
            return
        job = pickle.loads(stdin.read(struct.unpack("<Q", head)[0]))
        try:
            draw_solid(*job[1:])
            out.write(f"ok {job[0]}\n")
        except Exception as exc:  # noqa: BLE001
            out.write(f"error {job[0]} {type(exc).__name__}: "
                      f"{str(exc).splitlines()[0] if str(exc) else ''}\n")
        out.flush()


class Renderer:
    """A renderer process: started at once, used by :meth:`submit` and :meth:`wait`."""

    def __init__(self):
        self.proc = subprocess.Popen(
            [sys.executable, "-c", _BOOT, os.path.abspath(__file__)], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, close_fds=True)
        self._ids = iter(range(1, 1 << 62))
        #: whether it died of a signal while it drew (VTK crashed, most likely: drawing
        #: with VTK in the command's own process would take the command down with it)
        self.crashed = False
        self._lock = threading.Lock()
        self._buffer = b""

    def alive(self) -> bool:
        return self.proc.poll() is None

    def submit(self, path, pts, cd, tri, up_axis: str, title: str) -> int | None:
        """Send a solid to draw; its job id, or None when the renderer cannot take it."""
        with self._lock:
            if not self.alive():
                return None
            job = next(self._ids)
            data = pickle.dumps((job, str(path), pts, cd, tri, up_axis, title),
                                protocol=pickle.HIGHEST_PROTOCOL)
            try:
                self.proc.stdin.write(struct.pack("<Q", len(data)) + data)
                self.proc.stdin.flush()
            except OSError:
                return None
            return job

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
                        words[1] == str(job):
                    return words[0] == "ok"
                if words[:1] == ["unavailable"]:
                    return False
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                self.close()  # a renderer that hangs is not waited for again
                return False
            chunk = os.read(fd, 65536)
            if not chunk:  # it ended without an answer: killed by a signal is a crash
                self.crashed = (self.proc.wait() or 0) < 0
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


_renderer: Renderer | None = None


def wanted() -> bool:
    """Whether this process's pictures are drawn by a renderer: ``LUMITRACE_RENDERER`` is
    ``process`` (always) or ``inline`` (never); by default only for a command run at a
    terminal, whose user waits for it (0.5-0.8 s sooner), not for a farm's or a script's,
    which pays for its CPU (0.6-0.9 CPU s more: a second interpreter loads numpy and VTK).
    Never on one core, where a process of its own only adds its start."""
    mode = os.environ.get("LUMITRACE_RENDERER", "auto").lower()
    if mode == "inline" or (os.cpu_count() or 1) < 2:
        return False
    if mode == "process":
        return True
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def start_renderer() -> Renderer | None:
    """Start this process's renderer where it is :func:`wanted` (once; None where it is
    not, pyvista is not installed or the process cannot be started), to be used by the
    pictures this process draws."""
    global _renderer
    if _renderer is not None and _renderer.alive():
        return _renderer
    import importlib.util

    if not wanted() or importlib.util.find_spec("pyvista") is None:
        return None
    try:
        _renderer = Renderer()
    except OSError:
        _renderer = None
        return None
    atexit.register(stop_renderer)
    return _renderer


def renderer() -> Renderer | None:
    """The renderer started in this process, if it still runs."""
    return _renderer if _renderer is not None and _renderer.alive() else None


def abandon_renderer() -> None:
    """Kill this process's renderer at once (a picture it draws is no longer wanted: the
    set it was to join is being rolled back); the next :func:`start_renderer` starts
    another."""
    global _renderer
    if _renderer is not None:
        _renderer.proc.kill()
        _renderer.close()
        _renderer = None


def stop_renderer() -> None:
    """End this process's renderer, if one was started: at the process's end every
    picture it was given has been waited for, so it is not waited for itself."""
    abandon_renderer()
