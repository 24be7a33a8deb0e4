"""The cache folder, where lumitrace keeps what it can make again (the layout tables, the
kept scenes), with the reads it trusts and the writes it makes whole.

A kept file can hold a pickle, which runs code as it loads: it is read only where it is
this user's own, in a folder no one else may write. A file is written under a name of its
writer's own and renamed, so two writers leave one whole file.
"""
from __future__ import annotations

import os
import threading
from pathlib import Path


def cache_folder() -> Path | None:
    """Where lumitrace keeps what it can make again (None: nowhere): ``LUMITRACE_CACHE_DIR``
    (``off`` for nowhere), else ``$XDG_CACHE_HOME/lumitrace``, else ``~/.cache/lumitrace``."""
    env = os.environ.get("LUMITRACE_CACHE_DIR")
    if env:
        return None if env.lower() in ("off", "0", "none") else Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "lumitrace"


def owned(st: os.stat_result) -> bool:
    """Whether a file or folder is this user's and no one else may write it."""
    return st.st_uid == os.getuid() and not st.st_mode & 0o022


def open_kept(path: Path):
    """The file kept at ``path``, open for reading, where it is to be trusted: this user's,
    in a folder no one else may write (code, or a pickle, runs as it loads); else None
    (absent or unreadable too)."""
    try:
        if not owned(os.stat(path.parent)):
            return None
        f = open(path, "rb")
    except OSError:
        return None
    try:
        if owned(os.fstat(f.fileno())):
            return f
    except OSError:
        pass
    f.close()
    return None


def read_kept(path: Path) -> bytes | None:
    """The bytes kept at ``path`` where they are to be trusted (:func:`open_kept`); else
    None."""
    f = open_kept(path)
    if f is None:
        return None
    try:
        with f:
            return f.read()
    except OSError:
        return None


def write_kept(path: Path, data: bytes) -> bool:
    """Keep ``data`` at ``path``, in a folder only this user may write: written whole under
    a name of this process and thread, then renamed (two writers leave one whole file);
    False where it could not be."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        with open(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), "wb") as f:
            f.write(data)
        os.replace(tmp, path)
        return True
    except Exception:
        try:
            tmp.unlink()
        except OSError:
            pass
        return False
