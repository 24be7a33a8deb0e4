"""A stage's :class:`~lumitrace.scene.Scene`, kept on disk after it is read, so that a
trace of an unchanged stage does not load USD at all.

Loading USD and composing a stage cost a short run more than its photons (about 0.16 CPU
s of a small luminaire's 0.37 s run to 2%: more than a compiled tracer's whole run). A
scene is a pure function of the bytes of the files it was read from (its layers, the
emitters' IES and ray files), of what lumitrace and USD are, and of the request
(luminaire, time code, USD's plugin path). So
the read scene is kept with the SHA-256 of each of those files, and is taken again
only where every one of them holds the same bytes (hashed again at each run, not trusted
by its modification time; within a run, a file hashed when the scene was taken is not read
again to vouch for it while its stat, change time included, is what it was and settled).

Kept only where that is sound: a stage that composed whole (a missing sublayer or
reference, only a warning outside the luminaire, is a file whose appearance no digest
would see) and with no USD search path set (where a new file could change what an asset
path resolves to); and only where every file was last modified before the read began, by
more than a file system's time step (a file written while USD read it could pair its new
bytes with the old scene; the next run keeps it). One file is the exception: the
result layer lumitrace sublayers into the stage, rewritten by every run, holds only
lumitrace's results, which the reader skips; the run that wrote it records its new
digest beside the entry where the scene was read with lumitrace's own bytes there
(:func:`vouch`), and while it holds the bytes lumitrace last wrote its time does not
make it unsettled. The entry
is a table file (:mod:`lumitrace.table_cache`: this user's, in a folder no one else may
write, arrays mapped), one per stage and request, under the cache folder, the
:data:`MOST_ENTRIES` used last; ``LUMITRACE_CACHE_DIR=off`` keeps none.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.util
import os
import time
from pathlib import Path

from ..digests import file_stamp, readable_digest
from ..cache_files import cache_folder, read_kept, write_kept
from ..scene import Scene
from ..schema import PLUGIN_PATH_VARIABLE
from ..table_cache import read_table, sources_stamp, write_table

#: Files last modified less than this before a read began are not trusted to be the bytes
#: USD read (coarse file system clocks, a writer still at work): ns.
SETTLED_NS = 2_000_000_000
#: Scenes whose arrays are larger than this (bytes) are not kept: writing one costs its
#: first run about as much as reading it saves a later one (a 1M-triangle scene's 116 MB:
#: +0.7-1.1 s to its first run, -1.2 s to each later one, measured on a 2-core machine),
#: and the cache is for the many runs of a luminaire, not a copy of every large stage.
MOST_BYTES = 32 * 2**20
#: Entries kept at most: writing one more removes those used least recently (a night of
#: variants leaves no pile of scenes behind).
MOST_ENTRIES = 256
#: The environment variable of USD's search paths: where one is set, nothing is kept (the
#: plugin path, file formats and resolvers, is part of the request).
SEARCH_PATH_VARIABLE = "PXR_AR_DEFAULT_SEARCH_PATH"


def read_stage(path: str | Path, luminaire: str | None = None, *,
               time_code: float | None = None) -> Scene:
    """:func:`lumitrace.stage.reader.read_stage`, taken from the kept scene where the
    stage and every file it was read from are unchanged; else read (loading USD) and
    kept where that is sound (see the module's notes)."""
    entry = entry_path(path, luminaire, time_code)
    if entry is not None:
        scene = _kept_scene(entry)
        if scene is not None:
            return scene
    started = time.time_ns()
    from . import reader

    scene, whole = reader.read_stage_file(path, luminaire, time=time_code)
    if entry is not None and whole:
        _keep(entry, scene, started)
    return scene


def entry_path(path, luminaire: str | None = None, time_code: float | None = None
               ) -> Path | None:
    """The file that keeps the scene of this request (stage, luminaire, time code), or
    None where nothing is to be kept."""
    folder = cache_folder()
    if folder is None or os.environ.get(SEARCH_PATH_VARIABLE):
        return None
    try:
        real = os.path.realpath(path)
        if not os.path.isfile(real):
            return None
    except (OSError, ValueError):
        return None
    request = repr((real, luminaire, None if time_code is None else float(time_code),
                    os.environ.get(PLUGIN_PATH_VARIABLE, "")))
    key = hashlib.blake2b(request.encode(), digest_size=10).hexdigest()
    return folder / f"scene-{key}.table"


def _kept_scene(entry: Path) -> Scene | None:
    """The scene kept in ``entry`` where it was kept by this lumitrace and USD and each
    file it was read from holds the bytes it held then; else None."""
    kept = _entry(entry)
    if kept is None or not all(_holds(*f) for f in kept["files"]):
        return None
    with contextlib.suppress(OSError):
        os.utime(entry)  # used now: the last to go
    return kept["scene"]


def _entry(entry: Path) -> dict | None:
    """The entry kept in ``entry`` where this lumitrace and USD kept it in this layout
    (a stamp, the files as (path, digest, light stamp), a scene; the files as read
    ``as_read``, and as they stand ``files``: a result layer at the digest vouched for
    it); else None."""
    found, kept = read_table(entry)
    if not found or not isinstance(kept, dict) or kept.get("stamp") != validity_stamp() \
            or not isinstance(kept.get("scene"), Scene):
        return None
    try:
        files = [(str(f), str(d), str(s)) for f, d, s in kept.get("files", ())]
    except (TypeError, ValueError):  # not an entry of this layout
        return None
    as_read, vouched = files, _vouched(entry)
    if vouched is not None:  # the result layer as lumitrace last rewrote it
        files = [(f, vouched[2], s) if (f, d) == vouched[:2] else (f, d, s)
                 for f, d, s in files]
    return {**kept, "files": files, "as_read": as_read}


def _holds(file: str, digest: str, light_stamp: str) -> bool:
    """Whether ``file`` holds the bytes (and, a light's file, the stamp) it was kept with."""
    return not (light_stamp and _stamp_of(file) != light_stamp) and \
        _digest(file) == digest


#: The digests this process took, by file: (the file's device, inode, size, modification
#: and change times then, its SHA-256), kept only where those times were settled then.
_taken: dict[str, tuple[tuple, str]] = {}


def _digest(file: str) -> str | None:
    """SHA-256 of ``file``'s bytes (None: unreadable). A run checks its files when it
    takes a scene and again when it vouches for it: the second time a file whose stat is
    the one it had when this process hashed it, then settled (modified and changed more
    than :data:`SETTLED_NS` before), is not read again. Any write since would have moved
    its change time, which no one can set back."""
    try:
        st = os.stat(file)
    except OSError:
        return None
    stat = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    known = _taken.get(file)
    if known is not None and known[0] == stat:
        return known[1]
    hashed_at = time.time_ns()
    digest = readable_digest(file)
    if digest is not None and max(st.st_mtime_ns, st.st_ctime_ns) <= hashed_at - SETTLED_NS:
        _taken[file] = (stat, digest)
    return digest


def vouch(path, luminaire: str | None, time_code: float | None, layer: Path,
          digest: str) -> None:
    """Keep the kept scene of this request valid after lumitrace itself rewrote its result
    layer ``layer`` (``digest``: SHA-256 of the bytes it wrote), where the scene was read
    with the bytes lumitrace wrote there before and every other file is unchanged: the
    reader skips lumitrace's own results (the stand-in light in its variant,
    ``lumitrace:result:*``), so the scene read with the new layer is the one kept. A scene
    read with anyone else's bytes there is not vouched for (they may have added to it). A
    sublayered run's next run then takes the kept scene instead of loading USD again.

    The entry itself is not rewritten (its arrays are up to :data:`MOST_BYTES`): a small
    file beside it says which digest now stands for the layer's digest in it."""
    real = os.path.realpath(layer)
    before = _last_written(real)
    _note_written(real, digest)
    entry = entry_path(path, luminaire, time_code)
    kept = None if entry is None or before is None else _entry(entry)
    if kept is None:
        return
    others = [f for f in kept["files"] if f[0] != real]
    if (real, before) not in [f[:2] for f in kept["files"]] or \
            not all(_holds(*f) for f in others):
        return  # read with other bytes there, or another file changed
    read_with = next(d for f, d, _ in kept["as_read"] if f == real)
    write_kept(_vouch_path(entry), "\n".join((real, read_with, digest)).encode())


def _vouch_path(entry: Path) -> Path:
    """The small file beside ``entry`` that says which bytes of its result layer stand
    for those it was read with: the layer's path, its digest in the entry, the new one."""
    return entry.with_suffix(".vouched")


def _vouched(entry: Path) -> tuple[str, str, str] | None:
    """The (layer, digest in the entry, digest that stands for it) vouched for ``entry``."""
    data = read_kept(_vouch_path(entry))
    lines = [] if data is None else data.decode("utf-8", "replace").split("\n")
    return tuple(lines) if len(lines) == 3 else None


def _written_path(layer: str) -> Path | None:
    """Where the digest of what lumitrace last wrote to the result layer ``layer`` (a real
    path) is kept (None: nothing is kept)."""
    folder = cache_folder()
    if folder is None:
        return None
    key = hashlib.blake2b(layer.encode(), digest_size=10).hexdigest()
    return folder / f"written-{key}.digest"


def _note_written(layer: str, digest: str) -> None:
    path = _written_path(layer)
    if path is not None:
        write_kept(path, digest.encode())


def _last_written(layer: str) -> str | None:
    """The digest of the bytes lumitrace last wrote to the result layer ``layer``."""
    path = _written_path(layer)
    data = None if path is None else read_kept(path)
    return None if data is None else data.decode("ascii", "replace")


def _keep(entry: Path, scene: Scene, started_ns: int) -> None:
    """Keep ``scene`` in ``entry`` with its files' digests, where that is sound."""
    if _array_bytes(scene) > MOST_BYTES:
        return
    # a light's IES or ray file is known by its size and time too (a touched file makes
    # another light): such a file's stamp must still be the scene's
    stamps = {}
    for e in scene.emitters:
        if e.ies is not None and e.ies.file:
            stamps[os.path.realpath(e.ies.file)] = e.ies.stamp
        if e.rays:
            stamps[os.path.realpath(e.rays)] = e.rays_stamp
    files = []
    for file in sorted(scene.input_files()):
        try:
            before = os.stat(file)
            digest = _digest(file)
            after = os.stat(file)
        except OSError:
            return
        # (a result layer holding the bytes lumitrace last wrote there is read for no
        # value of the scene: its time does not matter, the last run has just written it)
        settled = after.st_mtime_ns <= started_ns - SETTLED_NS or \
            digest == _last_written(file)
        if (before.st_mtime_ns, before.st_size) != (after.st_mtime_ns, after.st_size) \
                or not settled or digest is None:
            return
        files.append((file, digest, stamps.get(file, "")))
    if not files:
        return
    if write_table(entry, {"stamp": validity_stamp(), "files": files, "scene": scene},
                   most_bytes=MOST_BYTES):
        with contextlib.suppress(OSError):  # vouched for the entry before
            _vouch_path(entry).unlink()
        _drop_least_used(entry.parent)


def _drop_least_used(folder: Path) -> None:
    """Remove the entries used least recently beyond :data:`MOST_ENTRIES`, what was
    vouched for them, and the digests of result layers written least recently beyond
    as many."""
    for pattern in ("scene-*.table", "written-*.digest"):
        kept = []
        for path in folder.glob(pattern):
            with contextlib.suppress(OSError):
                kept.append((path.stat().st_mtime_ns, path))
        kept.sort(reverse=True)
        for _, path in kept[MOST_ENTRIES:]:
            with contextlib.suppress(OSError):
                path.unlink()
    for path in folder.glob("scene-*.vouched"):
        if not path.with_suffix(".table").exists():
            with contextlib.suppress(OSError):
                path.unlink()


def _array_bytes(scene: Scene) -> int:
    """The bytes of the scene's geometry arrays (what its entry's size is made of)."""
    frames = sum(f.local.nbytes for f in scene.part_frames if f is not None)
    return (scene.triangles.nbytes + scene.material_index.nbytes + scene.part_index.nbytes
            + frames)


def _stamp_of(file: str) -> str:
    """A light file's stamp as the reader takes it; empty where it cannot be read."""
    try:
        return file_stamp(file)
    except OSError:
        return ""


@functools.lru_cache(maxsize=1)
def validity_stamp() -> str:
    """What a kept scene is valid for: lumitrace's sources, its USD schema's files and
    the installed USD (its package's files, found without loading it)."""
    parts = [sources_stamp()]
    from ..schema import SCHEMA_DIR

    files = [SCHEMA_DIR / "plugInfo.json", SCHEMA_DIR / "generatedSchema.usda"]
    spec = importlib.util.find_spec("pxr")
    if spec is not None and spec.submodule_search_locations:
        usd = Path(next(iter(spec.submodule_search_locations))) / "Usd"
        files += [usd / "__init__.py", *sorted(usd.glob("_usd*"))]
    for file in files:
        try:
            st = os.stat(file)
            parts.append(f"{file} {st.st_size} {st.st_mtime_ns}")
        except OSError:
            parts.append(f"{file} -")
    return hashlib.blake2b("\0".join(parts).encode(), digest_size=10).hexdigest()
