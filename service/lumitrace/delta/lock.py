"""One stage, one writer of its edits: a lock file beside the stage, held with ``flock``
while a service runs (and while ``lumitrace edits merge`` or ``discard`` changes the edits
layer, which a running service would otherwise write back from memory).

Two services on one stage would each hand out revisions and each rewrite the edits layer
from memory, losing the other's accepted deltas; the second therefore refuses at start,
naming the first (its process and port, written inside the lock file). The operating
system releases an ``flock`` when its process dies, however it dies (kill -9 included),
so a lock file left by a dead service is simply taken over: it is never mistaken for a
live one, and no process id is ever guessed alive.

A path names the lock beside the file; a hard link (or a bind mount) gives one file
another path, and a save by rename gives it a new inode under the same path. So the lock
is also taken on the file's identity as it is when a service starts: each holder keeps an
entry in this user's private folder of held stages, and a second one whose stage is the
same file (same device and inode, now) as a held one's refuses alike.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import os
import secrets
import stat
import tempfile
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
        self._entry: tuple[Path, int] | None = None  # in the held stages' folder

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
        try:
            lock._entry = _hold_identity(Path(stage_path), path, doing)
        except BaseException:
            lock.release()
            raise
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
        if self._entry is not None:
            entry, fd = self._entry
            self._entry = None
            with contextlib.suppress(OSError):
                entry.unlink()
            os.close(fd)
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


def held_folder() -> Path | None:
    """This user's private folder of held stages (mode 0700, made if missing): in
    ``$XDG_RUNTIME_DIR`` or the temporary folder; None where none can be had (a service
    then locks by path alone)."""
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    base = Path(runtime) / "lumitrace" if runtime else \
        Path(tempfile.gettempdir()) / f"lumitrace-{os.geteuid()}"
    folder = base / "stages-held"
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        st = os.lstat(folder)
    except OSError:
        return None
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.geteuid() or st.st_mode & 0o077:
        return None  # not this user's alone: nothing in it can be trusted
    return folder


def _hold_identity(stage: Path, lock_file: Path, doing: str | None
                   ) -> tuple[Path, int] | None:
    """Refuse where a live holder's stage is now the same file as ``stage``; else add
    this process's entry (held with ``flock`` while it lives) and return (its path, fd)."""
    folder = held_folder()
    if folder is None:
        return None
    guard = os.open(folder / ".lock", os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
    try:
        fcntl.flock(guard, fcntl.LOCK_EX)  # one look-and-add at a time
        for entry in folder.glob("*.json"):
            holder = _live_holder(entry)
            if holder is None:
                continue
            try:
                same = os.path.samefile(holder.get("stage", ""), stage)
            except (OSError, TypeError):
                same = False
            if same:
                who = _holder_of(holder.get("lock"))
                what = f"{stage} is the same file as {holder.get('stage')}, "
                if doing is None:
                    raise LumitraceError(what + f"already served by {who}: one stage, one "
                                         "service (stop that one first)")
                raise LumitraceError(what + f"served by {who}: stop it before {doing} (it "
                                     "would write its edits back)")
        entry = folder / f"{os.getpid()}-{secrets.token_hex(8)}.json"
        fd = os.open(entry, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
        fcntl.flock(fd, fcntl.LOCK_EX)
        os.write(fd, json.dumps({"stage": str(Path(stage).resolve()),
                                 "lock": str(lock_file)}).encode())
        return entry, fd
    finally:
        os.close(guard)


def _live_holder(entry: Path) -> dict | None:
    """What a live holder's entry says; None for one whose process is gone (removed)."""
    try:
        fd = os.open(entry, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError:  # held: its process lives
            try:
                info = json.loads(os.pread(fd, 1 << 16, 0) or b"{}")
            except (OSError, ValueError):
                return None
            return info if isinstance(info, dict) else None
        with contextlib.suppress(OSError):
            entry.unlink()  # its process is gone (we hold the folder's lock)
        return None
    finally:
        os.close(fd)


def _holder_of(lock_file) -> str:
    """Who holds a stage, in words, from what its holder wrote in its lock file."""
    try:
        fd = os.open(lock_file, os.O_RDONLY)
    except (OSError, TypeError):
        return "another service"
    try:
        return _read_holder(fd)
    finally:
        os.close(fd)
