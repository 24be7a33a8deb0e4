"""Sublayering the result layer into the stage's root layer, once, without losing edits."""
from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import stat
import sys
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path

from ..errors import OutputError, OutputWarning
from ..atomic import fsync_path
from ..filenames import RESULT_LAYER_SUFFIX
from .ownership import belongs_to
from .usda_text import insert_sublayer_text, sublayer_entries
from ..stage.pxr_messages import tf_message


class ResultLayerWarning(OutputWarning):
    """The result layer was written but could not be sublayered into the stage."""


def file_mode(path: Path, missing: int | None = 0o644) -> int | None:
    """The permission bits of ``path``; ``missing`` where it has none (gone)."""
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except OSError:
        return missing


def _resolves_to(entry: str, root_dir: Path, target: Path) -> bool:
    if "://" in entry or entry.startswith("@"):
        return False
    candidate = Path(entry) if os.path.isabs(entry) else root_dir / entry
    return os.path.normcase(os.path.normpath(candidate)) == \
        os.path.normcase(os.path.normpath(target))


def _warn(message: str) -> None:
    warnings.warn(message, ResultLayerWarning, stacklevel=4)  # the caller


#: Attempts of the compare-and-swap edit before giving up (each after the file changed).
CAS_ATTEMPTS = 20


def _open_bytes_copy(data: bytes, stage: Path):
    """An anonymous Sdf layer holding the root layer as read from ``data``."""
    from pxr import Sdf, Tf

    try:
        if data.startswith(b"#usda"):
            layer = Sdf.Layer.CreateAnonymous(".usda")
            if layer.ImportFromString(data.decode("utf-8")):
                return layer
        layer = Sdf.Layer.OpenAsAnonymous(str(stage))
    except (Tf.ErrorException, UnicodeDecodeError) as exc:
        raise OutputError(f"cannot read the stage's root layer: {tf_message(exc)}",
                          str(stage)) from exc
    if layer is None:
        raise OutputError("cannot read the stage's root layer", str(stage))
    return layer


def _edited_bytes(stage: Path, data: bytes, entry: str | None, root,
                  remove: tuple[str, ...] = ()) -> bytes:
    """The root layer's bytes with ``entry`` first in its subLayers (None: none added) and
    the entries ``remove`` taken out: a text edit of a .usda file (comments and formatting
    kept), else Sdf's export in the file's format."""
    if data.startswith(b"#usda"):
        text = insert_sublayer_text(data.decode("utf-8"), entry, root, remove)
        if text is not None:
            return text.encode("utf-8")
    from pxr import Sdf

    copy = Sdf.Layer.CreateAnonymous(".usda")
    copy.TransferContent(root)
    for old in remove:
        copy.subLayerPaths.remove(old)
    if entry is not None:
        copy.subLayerPaths.insert(0, entry)
    fmt = "usda" if data.startswith(b"#usda") else "usdc"
    fd, tmp = tempfile.mkstemp(prefix=f".{stage.stem}.", suffix=f".tmp.{fmt}",
                               dir=stage.parent)
    os.close(fd)
    try:
        if not copy.Export(tmp, args={"format": fmt} if stage.suffix.lower() == ".usd" else {}):
            raise OutputError("Sdf could not export the root layer", str(stage))
        return Path(tmp).read_bytes()
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


_AT_FDCWD, _RENAME_EXCHANGE = -100, 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap the files at ``a`` and ``b`` in one step (Linux ``renameat2`` with
    ``RENAME_EXCHANGE``); False where the system or the file system cannot."""
    libc = _libc()
    fn = getattr(libc, "renameat2", None) if libc is not None else None
    if fn is None:
        return False
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


_LIBC: list = []


def _libc():
    if not _LIBC:
        try:
            _LIBC.append(ctypes.CDLL(None, use_errno=True))
        except OSError:
            _LIBC.append(None)
    return _LIBC[0]


def _swap_in(tmp: Path, target: Path, data: bytes, expected: bytes) -> bool | None:
    """Put ``tmp`` (holding ``data``) at ``target`` if ``target`` holds ``expected`` at
    that instant: the files are exchanged, and what came out is compared; a save that
    landed in between is swapped back (and one landing after our swap is kept as the
    newest). True: done; False: the file changed; None: no atomic exchange here."""
    if not _exchange(tmp, target):
        return None
    if tmp.read_bytes() == expected:
        return True
    _exchange(tmp, target)  # a newer save was swapped out: put it back
    if tmp.read_bytes() != data:
        _exchange(tmp, target)  # and another landed on ours meanwhile: it is the newest
    return False


def _replace_keeping_identity(target: Path, data: bytes, expected: bytes, st) -> bool:
    """Write ``data`` over ``target`` if it still holds ``expected``; keep its inode when
    it has other hard links or another owner we cannot give the new file, else swap a
    temporary file with the same mode and owner in for it (atomically compared: see
    :func:`_swap_in`). False when the file changed."""
    in_place = st.st_nlink > 1
    if not in_place:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}",
                                   dir=target.parent)
        tmp = Path(tmp)
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            os.chmod(tmp, stat.S_IMODE(st.st_mode))
            if (st.st_uid, st.st_gid) != (os.geteuid(), os.getegid()):
                try:
                    os.chown(tmp, st.st_uid, st.st_gid)
                except PermissionError:
                    in_place = True
            if not in_place:
                if target.read_bytes() != expected:   # compare ...
                    return False
                swapped = _swap_in(tmp, target, data, expected)  # ... and swap
                if swapped is None:  # no atomic exchange: a rename, with its window
                    os.replace(tmp, target)
                    tmp = None
                elif not swapped:
                    return False
        finally:
            if tmp is not None:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
        if not in_place:
            fsync_path(target.parent)
            return True
    with open(target, "r+b") as fh:
        if fh.read() != expected:
            return False
        fh.seek(0)
        fh.write(data)
        fh.truncate()
        fh.flush()
        os.fsync(fh.fileno())
    return True


def _other_result_of(entry: str, stage: Path, layer_path: Path) -> bool:
    """Whether the subLayers ``entry`` is another result layer of ``stage`` than
    ``layer_path`` (one from an earlier ``--out``, or a moved stage's, now gone): a stage
    composes one result, the newest."""
    if not entry.endswith(RESULT_LAYER_SUFFIX) or _resolves_to(entry, stage.parent, layer_path):
        return False
    if "://" in entry or entry.startswith("@"):
        return False
    path = Path(entry) if os.path.isabs(entry) else stage.parent / entry
    if not path.exists():
        return path.name == layer_path.name
    return belongs_to(path, stage)


@dataclass(frozen=True)
class RootEdit:
    """What :func:`sublayer_into_root` found and did: the root layer's bytes it read
    (``read``) and the bytes it wrote in their place (``wrote``; None: nothing written).
    A watcher of the stage compares these with what it last loaded, so that a save by
    someone else, even one landing in the middle of the edit, is never taken for ours."""

    read: bytes | None = None
    wrote: bytes | None = None


def sublayer_into_root(stage: Path, layer_path: Path) -> RootEdit:
    """Put the result layer (``./NAME.lumitrace.usda`` beside the stage, or its path
    relative to the stage's folder) first in the stage root layer's subLayers, once, and
    take out the stage's other result layers (one stage, one current result).

    A compare-and-swap: the file is read, the edit made on that copy, and the file is
    replaced only if it still holds exactly what was read; a save by anyone else in between
    makes it start again. Nothing but the subLayers entry changes (a .usda file's text is
    edited in place); the file keeps its mode, owner and hard links.
    """
    rel = Path(os.path.relpath(layer_path, Path(stage).absolute().parent)).as_posix()
    entry = rel if rel.startswith("../") else "./" + rel
    if stage.suffix.lower() == ".usdz":
        _warn(f"{stage}: a .usdz package is not modified; add {entry} to its subLayers "
              f"(or open {layer_path.name} over it) to see the result in the stage")
        return RootEdit()
    target = Path(os.path.realpath(stage))   # edit the file, not a symlink to it
    for _ in range(CAS_ATTEMPTS):
        try:
            data = target.read_bytes()
            st = target.stat()
        except OSError as exc:
            raise OutputError(f"cannot read the stage's root layer: {exc.strerror}",
                              str(stage)) from exc
        listed = _plain_sublayers(data)  # a run whose layer is in place: no USD loaded
        if listed is not None and _in_place(listed, stage, layer_path):
            _sync_open_root(stage, entry, layer_path)
            return RootEdit(data)
        root = _open_bytes_copy(data, target)
        if _in_place(root.subLayerPaths, stage, layer_path):
            _sync_open_root(stage, entry, layer_path)
            return RootEdit(data)
        stale = tuple(p for p in root.subLayerPaths if _other_result_of(p, stage, layer_path))
        present = any(_resolves_to(p, stage.parent, layer_path) for p in root.subLayerPaths)
        if not (os.access(target, os.W_OK) and os.access(target.parent, os.W_OK)):
            _warn(f"{stage}: the root layer is not writable; the result is in "
                  f"{layer_path.name} but is not sublayered into the stage")
            return RootEdit(data)
        new = _edited_bytes(target, data, None if present else entry, root, stale)
        try:
            if _replace_keeping_identity(target, new, data, st):
                _sync_open_root(stage, entry, layer_path)
                return RootEdit(data, new)
        except OSError as exc:
            raise OutputError(f"cannot sublayer the result layer into the stage: {exc}",
                              str(stage)) from exc
    raise OutputError(f"the stage changed on disk {CAS_ATTEMPTS} times while the result "
                      "layer was being sublayered; run again", str(stage))


def reload_if_open(path: Path) -> None:
    """Reload a layer this process has open, so its stages see the new file (none is,
    where USD's Sdf is not loaded)."""
    if "pxr.Sdf" not in sys.modules:
        return
    from pxr import Sdf

    layer = Sdf.Layer.Find(str(path))
    if layer is not None:
        layer.Reload(force=True)


def _plain_sublayers(data: bytes) -> list[str] | None:
    """The subLayers of a root layer's bytes where its ``.usda`` text lists them plainly
    (:func:`~.usda_text.sublayer_entries`); None where USD must read them."""
    if not data.startswith(b"#usda"):
        return None
    try:
        return sublayer_entries(data.decode("utf-8"))
    except UnicodeDecodeError:
        return None


def _in_place(entries, stage: Path, layer_path: Path) -> bool:
    """Whether the subLayers ``entries`` hold the result layer and no other of the
    stage's: nothing to edit."""
    return any(_resolves_to(p, stage.parent, layer_path) for p in entries) and \
        not any(_other_result_of(p, stage, layer_path) for p in entries)


def _sync_open_root(stage: Path, entry: str, layer_path: Path) -> None:
    """Bring an open instance of the root layer in line with the file: reload it when it
    has no unsaved edits, otherwise add the sublayer entry in memory (keeping the edits).
    (No layer is open where USD's Sdf is not loaded.)"""
    if "pxr.Sdf" not in sys.modules:
        return
    from pxr import Sdf

    layer = Sdf.Layer.Find(str(stage))
    if layer is None:
        return
    if _in_place(layer.subLayerPaths, stage, layer_path):
        return
    stale = [p for p in layer.subLayerPaths if _other_result_of(p, stage, layer_path)]
    if layer.dirty:
        for old in stale:
            layer.subLayerPaths.remove(old)
        if not any(_resolves_to(p, stage.parent, layer_path) for p in layer.subLayerPaths):
            layer.subLayerPaths.insert(0, entry)
    else:
        layer.Reload(force=True)


