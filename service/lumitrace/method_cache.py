"""The compiled code of dataclasses' generated methods, kept on disk between commands; and
the cache folder with its trusted reads and whole writes (the layout tables' too).

Python 3.11 makes each dataclass's ``__init__``, ``__repr__``, ``__eq__`` (and a frozen
one's ``__setattr__``, ``__delattr__``, ``__hash__``) by compiling their source text as
the class is made: a ``trace`` makes 46 classes, 233 methods, about 45 ms of its start
(a tenth of the import floor). Compiling the same text gives the same code, so the code
is kept, keyed by the text itself, and read back: one ``marshal.loads``, about 1.5 ms.
The ``lumitrace`` command installs this before lumitrace loads (standard library only, so
the entry point loads it by its file); importing lumitrace as a library leaves the
interpreter's ``dataclasses`` as it is.

The file is ``dataclass-methods-TAG.marshal`` (TAG: the interpreter's, as ``cpython-311``)
in the cache folder (:func:`cache_folder`, the layout tables' too), written at exit when this process
compiled text the file lacked; like a table, it is read only when it is this user's, in
a folder no one else may write (it holds code).
"""
from __future__ import annotations

import atexit
import dataclasses
import marshal
import os
import sys
import threading
from pathlib import Path
from types import CodeType

#: Texts kept at most: lumitrace's own classes take about 250; a file past this (classes
#: made on the fly, by tests or another program) starts again from this process's.
MOST = 4000
_codes: dict[str, CodeType] = {}
_used: set[str] = set()
_new = False
_lock = threading.Lock()


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


def _path() -> Path | None:
    folder = cache_folder()
    tag = sys.implementation.cache_tag
    return None if folder is None or tag is None else \
        folder / f"dataclass-methods-{tag}.marshal"


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


def _read(path: Path) -> dict[str, CodeType]:
    """The codes kept at ``path``; none where there are none to trust or read."""
    data = read_kept(path)
    try:
        codes = marshal.loads(data) if data is not None else {}
    except Exception:  # cut short, or another interpreter's format
        return {}
    return codes if isinstance(codes, dict) else {}


def _exec(source, globals=None, locals=None, /):
    """``exec`` as dataclasses calls it, with the code of a text compiled before taken
    from the kept ones (compiled as exec would: no future flags of this module)."""
    global _new
    if type(source) is str:
        code = _codes.get(source)
        if code is None:
            code = compile(source, "<string>", "exec", dont_inherit=True)
            with _lock:
                _codes[source] = code
                _new = True
        _used.add(source)
        source = code
    return exec(source, globals, locals)


def save() -> None:
    """Keep the codes this process compiled, merged with what the file holds now; never
    raises."""
    path = _path()
    if not _new or path is None:
        return
    with _lock:
        codes = {**_read(path), **_codes}
        if len(codes) > MOST:
            codes = {k: v for k, v in _codes.items() if k in _used}
    write_kept(path, marshal.dumps(codes))


def install() -> None:
    """Make dataclasses take kept code from now on in this process, and keep at exit what
    it compiles anew (nothing where there is no cache folder)."""
    path = _path()
    if path is None or getattr(dataclasses, "exec", None) is _exec:
        return
    _codes.update(_read(path))
    dataclasses.exec = _exec  # the module's global name: shadows the built-in there alone
    atexit.register(save)
