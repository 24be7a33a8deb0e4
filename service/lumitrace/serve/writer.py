"""The service's writer: one thread that writes the newest result handed to it, so that the
engine goes on tracing while a done revision's files and pictures are written."""
from __future__ import annotations

import threading
from typing import Callable, ContextManager

from ..photometry.solid_render import kept_window


class Writer:
    """A thread that writes the newest result handed to it: one not yet begun when a newer
    one comes is dropped (the newer supersedes it), so writes never queue up."""

    def __init__(self, failed: Callable[[Exception], None],
                 around: Callable[[], ContextManager] = kept_window):
        """``failed(exc)`` hears of a write that raised; the thread runs inside ``around()``:
        by default the photometric solids its writes draw here (no renderer) share one
        window, each after the first in about half the time."""
        self._around = around
        self._cv = threading.Condition()
        self._job: Callable[[], None] | None = None
        self._busy = False
        #: whether the job handed over last (queued or running) writes the files alone
        self._cheap = False
        self._closed = False
        self._failed = failed
        self._thread = threading.Thread(target=self._run, name="lumitrace-writer",
                                        daemon=True)
        self._thread.start()

    def put(self, job: Callable[[], None], cheap: bool = False) -> None:
        """Hand ``job`` over (``cheap``: it writes the files, no pictures)."""
        with self._cv:
            self._job, self._cheap = job, cheap
            self._cv.notify_all()

    def wait_cheap(self, stop: Callable[[], bool], poll: float = 0.005) -> None:
        """Wait while a cheap write is queued or running, until ``stop()`` (polled every
        ``poll`` s) says not to."""
        with self._cv:
            while self._cheap and (self._job is not None or self._busy) and not stop():
                self._cv.wait(poll)

    def flush(self) -> None:
        """Wait until what was handed over is written."""
        with self._cv:
            while self._job is not None or self._busy:
                self._cv.wait()

    def close(self) -> None:
        self.flush()
        with self._cv:
            self._closed = True
            self._cv.notify_all()
        self._thread.join()

    def _run(self) -> None:
        with self._around():
            self._main()

    def _main(self) -> None:
        while True:
            with self._cv:
                while self._job is None and not self._closed:
                    self._cv.wait()
                if self._job is None:
                    return
                job, self._job, self._busy = self._job, None, True
            try:
                job()
            except Exception as exc:  # the writer never dies: the write is reported
                self._failed(exc)
            finally:
                with self._cv:
                    self._busy = False
                    self._cv.notify_all()
