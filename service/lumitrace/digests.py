"""How a file is known again: the SHA-256 of its bytes (outputs a run wrote, the files a
kept scene was read from, layers a service watches) and its size and modification time (a
light's IES or ray file, whose touch makes another light)."""
from __future__ import annotations

import hashlib
import os


def file_digest(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes, hex; raises OSError where it cannot be read."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def readable_digest(path: str | os.PathLike) -> str | None:
    """:func:`file_digest`, None where the file cannot be read."""
    try:
        return file_digest(path)
    except OSError:
        return None


def file_stamp(path: str | os.PathLike) -> str:
    """A file's size and modification time (ns), ``SIZE:MTIME``; raises OSError."""
    st = os.stat(path)
    return f"{st.st_size}:{st.st_mtime_ns}"
