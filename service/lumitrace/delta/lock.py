"""One stage, one writer of its edits: a lock file beside the stage, held with ``flock``
while a service runs (and while ``lumitrace edits merge`` or ``discard`` changes the edits
layer, which a running service would otherwise write back from memory).

Two services on one stage would each hand out revisions and each rewrite the edits layer
from memory, losing the other's accepted deltas; the second therefore refuses at start,
naming the first (its process and port, written inside the lock file). The operating
system releases an ``flock`` when its process dies, however it dies (kill -9 included),
so a lock file left by a dead service is simply taken over: it is never mistaken for a
live one, and no process id is ever guessed alive.
"""
from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path

from ..errors import LumitraceError
from ..filenames import stage_name

#: Suffix of the lock file: ``.NAME.lumitrace-serve.lock`` beside ``NAME.usda``.
LOCK_SUFFIX = ".lumitrace-serve.lock"


def lock_path(stage_path: str | os.PathLike) -> Path:
    """The lock file of a stage (hidden, beside the real file: a link to the stage, or
    another spelling of its path, names the same lock)."""
    stage = Path(stage_path).resolve()
    return stage.with_name("." + stage_name(stage) + LOCK_SUFFIX)


class StageLock:
    """The held lock of one stage; :meth:`acquire` takes it or says who holds it."""

    def __init__(self, path: Path, fd: int):
        self.path = path
        self._fd = fd

    @classmethod
    def acquire(cls, stage_path: str | os.PathLike, doing: str | None = None
                ) -> "StageLock":
        """Take the stage's lock, or raise :class:`LumitraceError` naming the service that
        holds it (``doing``: what was refused, for the message; default: serving it)."""
        path = lock_path(stage_path)
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise LumitraceError(f"cannot create the service's lock file: "
                                 f"{exc.strerror or exc}", str(path)) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = _read_holder(fd)
            os.close(fd)
            if doing is None:
                raise LumitraceError(f"{Path(stage_path)} is already served by {holder}: "
                                     "one stage, one service (stop that one first)") from None
            raise LumitraceError(f"{Path(stage_path)} is served by {holder}: stop it before "
                                 f"{doing} (it would write its edits back)") from None
        lock = cls(path, fd)
        lock.record()
        return lock

    def record(self, **info) -> None:
        """Write this process's id (and ``info``: port, url) into the lock file, for the
        message a second service gives."""
        data = json.dumps({"pid": os.getpid(), **info}).encode()
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, data, 0)

    def release(self) -> None:
        """Let the lock go (the file stays: removing it would let two services lock two
        different files of one name)."""
        if self._fd >= 0:
            try:
                os.ftruncate(self._fd, 0)
            finally:
                os.close(self._fd)
                self._fd = -1


def _read_holder(fd: int) -> str:
    """Who holds the lock, in words, from what it wrote in the file."""
    try:
        info = json.loads(os.pread(fd, 4096, 0) or b"{}")
    except (OSError, ValueError):
        info = {}
    if not isinstance(info, dict):
        info = {}
    pid, port = info.get("pid"), info.get("port")
    who = f"the service of process {pid}" if pid else "another service"
    if port:
        return f"{who} on port {port} ({info.get('url', '')})".replace(" ()", "")
    return f"{who} (still starting)"
