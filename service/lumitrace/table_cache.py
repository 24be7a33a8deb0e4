"""Tables fixed by a layout (a cube map's face size, the goniometer's grid), kept on disk so
that a run reads them instead of making them again: a pure function's results, pickled
once per argument under the user's cache folder and keyed on lumitrace's sources and numpy.

A short run spends as long making these tables (the pull-push pyramid, the cube map's
seams, the lat-long texture's taps, the goniometer's cell directions, the UGR table's
rooms: about 70 ms at face size 64) as tracing its photons. Reading them back takes about
a millisecond: their arrays are the files' pages, mapped. Any edit of a lumitrace source
or another numpy makes a new key, so a stale table is never read; a table written removes
its copies kept for other keys but the :data:`KEPT_STAMPS` written last.
The folder is ``LUMITRACE_CACHE_DIR``, else ``$XDG_CACHE_HOME/lumitrace``, else
``~/.cache/lumitrace``; ``LUMITRACE_CACHE_DIR=off`` keeps nothing on disk. A folder that
cannot be written, or a file that cannot be read, costs only the making; a file that is
not this user's, or a folder others may write, is never read (a pickle runs code).
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import mmap
import os
import pickle
import struct
import sys
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .cache_files import cache_folder, open_kept, write_kept

_PACKAGE = Path(__file__).resolve().parent


@functools.lru_cache(maxsize=1)
def sources_stamp() -> str:
    """A digest of every lumitrace source file (path, size, modification time), numpy's
    version and Python's: what a kept table is valid for."""
    h = hashlib.blake2b(digest_size=10)
    h.update(f"{np.__version__} {sys.version_info[:2]}".encode())
    folders = [str(_PACKAGE)]
    while folders:
        folder = folders.pop()
        entries = sorted(os.scandir(folder), key=lambda e: e.name)
        for e in entries:
            if e.name.endswith(".py") and e.is_file():
                st = e.stat()
                h.update(f"{e.path} {st.st_size} {st.st_mtime_ns}\0".encode())
            elif e.is_dir() and e.name != "__pycache__" and not e.name.startswith("."):
                folders.append(e.path)
    return h.hexdigest()


def _frozen(value: Any) -> Any:
    """``value`` with every array in it (in tuples, lists, frozen dataclasses) read-only:
    a table is shared by every caller."""
    if isinstance(value, np.ndarray):
        value.flags.writeable = False
    elif isinstance(value, (tuple, list)):
        for v in value:
            _frozen(v)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            _frozen(getattr(value, f.name))
    return value


def _path(fn: Callable, args: tuple) -> Path | None:
    """The file of ``fn``'s table for ``args``: NAME-ARGS-STAMP.table."""
    folder = cache_folder()
    if folder is None:
        return None
    key = hashlib.blake2b(repr(args).encode(), digest_size=8).hexdigest()
    return folder / f"{fn.__module__}.{fn.__qualname__}-{key}-{sources_stamp()}{SUFFIX}"


#: A table's file: MAGIC, the number of arrays' buffers and the pickle's length (two
#: little-endian u64), each buffer's offset and size (two u64 each), the pickle (protocol
#: 5, its arrays' data out of band), then each buffer, from an offset a multiple of 64.
SUFFIX = ".table"
MAGIC = b"LTTABLE1"
_HEAD = struct.Struct("<8sQQ")
_SPAN = struct.Struct("<QQ")


def read_table(path: Path) -> tuple[bool, Any]:
    """(True, the table) kept at ``path``; (False, None) where there is none to trust: a
    pickle runs code as it loads, so only a file this user wrote, in a folder no one else
    may write, is read (another's, or one in a shared folder, is made again instead).

    The arrays are the file's pages, mapped read-only, not copies: the pages a run does
    not use are not read (11 tables, 16 MB at face size 64: 1 ms, not 12 ms, to load)."""
    f = open_kept(path)
    if f is None:
        return False, None
    try:
        with f:
            kept = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        magic, count, length = _HEAD.unpack_from(kept, 0)
        start = _HEAD.size + count * _SPAN.size
        if magic != MAGIC or start + length > len(kept):
            return False, None
        view = memoryview(kept)
        buffers = []
        for i in range(count):
            offset, size = _SPAN.unpack_from(kept, _HEAD.size + i * _SPAN.size)
            if offset + size > len(kept):
                return False, None
            buffers.append(view[offset:offset + size])
        return True, pickle.loads(kept[start:start + length], buffers=buffers)
    except Exception:  # broken, or from another layout of the classes: remake
        return False, None


def _encoded(value: Any) -> bytearray:
    """``value`` in a table's file format (see :data:`MAGIC`)."""
    raws: list[memoryview] = []
    body = pickle.dumps(value, protocol=5,
                        buffer_callback=lambda b: raws.append(b.raw()))
    spans, offset = [], _HEAD.size + len(raws) * _SPAN.size + len(body)
    for raw in raws:
        offset = -(-offset // 64) * 64
        spans.append((offset, raw.nbytes))
        offset += raw.nbytes
    out = bytearray(offset)
    _HEAD.pack_into(out, 0, MAGIC, len(raws), len(body))
    for i, span in enumerate(spans):
        _SPAN.pack_into(out, _HEAD.size + i * _SPAN.size, *span)
    start = _HEAD.size + len(raws) * _SPAN.size
    out[start:start + len(body)] = body
    for (at, size), raw in zip(spans, raws):
        out[at:at + size] = raw
    return out


def write_table(path: Path, value: Any, most_bytes: int | None = None) -> bool:
    """Keep ``value`` at ``path`` (:func:`~lumitrace.cache_files.write_kept`: two makers
    of the same table leave one whole file), unless it is larger than ``most_bytes``;
    whether it was kept. Never raises."""
    try:
        data = _encoded(value)
    except Exception:
        return False
    if most_bytes is not None and len(data) > most_bytes:
        return False
    return write_kept(path, data)


def _write(path: Path, value: Any) -> None:
    """Keep the table ``value`` at ``path`` and drop its copies for other stamps."""
    if write_table(path, value):
        _drop_stale(path)


#: Other sources stamps whose tables are kept beside a new one's: another install of
#: lumitrace sharing the folder (a release and a checkout) keeps its own, not remade at
#: every run of either; an edited checkout's older stamps go.
KEPT_STAMPS = 2


def _drop_stale(path: Path) -> None:
    """Remove the same function's tables kept for sources stamps other than ``path``'s
    (an earlier format's files, another suffix, count as stamps of their own), but for the
    :data:`KEPT_STAMPS` most recently written."""
    name, _, own = path.name.rpartition("-")
    newest: dict[str, int] = {}
    others: list[tuple[str, Path]] = []
    for other in path.parent.glob(f"{name.rpartition('-')[0]}-*"):
        stamp = other.name.rpartition("-")[2]
        if stamp == own:
            continue
        try:
            when = other.stat().st_mtime_ns
        except OSError:
            continue
        newest[stamp] = max(newest.get(stamp, when), when)
        others.append((stamp, other))
    kept = set(sorted(newest, key=newest.__getitem__, reverse=True)[:KEPT_STAMPS])
    for stamp, other in others:
        if stamp not in kept:
            with contextlib.suppress(OSError):
                other.unlink()


def kept_table(fn: Callable) -> Callable:
    """Decorate a pure function of hashable arguments whose result is a table (arrays in
    tuples, lists or frozen dataclasses): made once per process (the result is shared and
    read-only) and kept on disk between processes. Only for arguments a layout fixes (a
    face size): a table that follows the data (a narrow beam's own grid) would leave a
    file per beam."""
    @functools.lru_cache(maxsize=16)
    def cached(*args):
        path = _path(fn, args)
        if path is not None:
            found, value = read_table(path)
            if found:
                return _frozen(value)
        value = _frozen(fn(*args))
        if path is not None:
            _write(path, value)
        return value

    functools.update_wrapper(cached, fn)
    cached.uncached = fn
    return cached
