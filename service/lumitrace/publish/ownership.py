"""Which existing files a run may replace: only the outputs lumitrace wrote for this stage.

The result layer records, in its customLayerData, the stage it belongs to (``stage``: its
path relative to the layer's folder, so the record survives moving or copying the folder
with the stage) and the SHA-256 of every other file the run wrote (``files``). Before
tracing, and again under the publishing lock, every output path that exists must be one of
those files, unchanged, and no output may be a file the stage reads (a layer, an IES
profile, a ray file). Outputs of a stage that no longer exists where its record says (a
moved stage, an ``--out`` folder outliving its stage) are taken over, with a warning; a
live stage's are never shared.
"""
from __future__ import annotations

import hashlib
import json
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

from ..digests import file_digest
from ..errors import OutputError
from ..filenames import RESULT_LAYER_SUFFIX, output_names
from .runs import layer_data

#: customLayerData keys (after ``lumitrace:``) of the ownership record.
STAGE_KEY, FILES_KEY = "stage", "files"


def stage_reference(stage_path: Path | None, layer_dir: Path) -> str:
    """How a result layer in ``layer_dir`` names its stage: the path relative to the
    layer's folder (POSIX separators); empty for a stage with no file of its own."""
    if stage_path is None:
        return ""
    return Path(os.path.relpath(Path(stage_path).absolute(), Path(layer_dir).absolute())
                ).as_posix()


def ownership_record(stage_path: Path | None, layer_dir: Path,
                     written: dict[str, Path]) -> dict[str, str]:
    """The customLayerData entries that claim the files ``written`` (output name -> the
    file holding its new content) for the stage."""
    digests = {name: file_digest(path) for name, path in sorted(written.items())}
    return {STAGE_KEY: stage_reference(stage_path, layer_dir),
            FILES_KEY: json.dumps(digests, sort_keys=True)}


def recorded_stage(layer: Path) -> Path | None:
    """The stage a result layer says it belongs to (its ``stage`` reference resolved
    against the layer's folder); None where it names none."""
    reference = layer_data(Path(layer)).get(STAGE_KEY)
    return Path(layer).parent / reference if reference else None


def belongs_to(layer: Path, stage: Path) -> bool:
    """Whether the result layer ``layer`` records ``stage`` as its stage."""
    recorded = recorded_stage(layer)
    return recorded is not None and _same_file(recorded, Path(stage))


@dataclass(frozen=True)
class Claim:
    """What a run may do to the files already in its output folder: ``dropped`` are the
    previous run's outputs this run does not write (removed with the commit), ``notes``
    warnings to give (outputs taken over from a stage that is gone)."""

    dropped: tuple[Path, ...] = ()
    notes: tuple[str, ...] = field(default=())


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.normcase(os.path.normpath(a)) == os.path.normcase(os.path.normpath(b))


def _recorded(layer: Path) -> tuple[str | None, dict[str, str] | None]:
    """(stage reference, file digests) of an existing result layer; (None, None) for a
    file that is no result layer lumitrace wrote."""
    data = layer_data(layer)
    try:
        files = json.loads(data[FILES_KEY])
    except (KeyError, ValueError, TypeError):
        return None, None
    if not isinstance(files, dict) or "runId" not in data:
        return None, None
    return data.get(STAGE_KEY), {str(k): str(v) for k, v in files.items()}


def _readable(path: Path) -> None:
    """Raise :class:`OutputError` saying so where ``path`` cannot be read: whether
    lumitrace wrote it cannot be told then (its record or its digest is unread)."""
    try:
        with open(path, "rb"):
            pass
    except OSError as exc:
        raise OutputError(f"cannot be read ({exc.strerror or exc}), so whether lumitrace "
                          "wrote it cannot be told: make it readable and writable by you "
                          "(chmod u+rw), or move it away", str(path)) from None


def _not_ours(path: Path, why: str) -> OutputError:
    return OutputError(f"{why}: lumitrace replaces only the files it wrote for this stage; "
                       "move it away, or write the outputs to a folder of their own (--out)",
                       str(path))


def claim_outputs(stage_path: Path | None, paths: dict[str, Path],
                  inputs: Iterable[str] = ()) -> Claim:
    """Check that a run of the stage at ``stage_path`` may write ``paths`` (output key ->
    path, the result layer under ``result_layer``): raises :class:`OutputError` naming the
    first file it may not replace. ``inputs`` are the real paths of the files the stage
    reads."""
    layer = Path(paths["result_layer"])
    return claim_files(stage_path, layer, _recorded, paths.values(), inputs,
                       output_names(layer.name[:-len(RESULT_LAYER_SUFFIX)]))


def claim_files(stage_path: Path | None, record: Path, read_record, paths: Iterable[Path],
                inputs: Iterable[str] = (), names: Iterable[str] = ()) -> Claim:
    """The ownership rules, for any record of the files lumitrace wrote for a stage (a
    result layer, a datasheet's record): ``record`` (one of ``paths``) is read by
    ``read_record(record)`` -> (stage reference, {file name: SHA-256}), (None, None) for
    a file that is no such record. Raises :class:`OutputError` naming the first of
    ``paths`` that may not be replaced; the claim drops the recorded files among
    ``names`` that this write does not make."""
    paths = [Path(p) for p in paths]
    record = Path(record)
    folder = record.parent
    what = "result layer" if record.name.endswith(RESULT_LAYER_SUFFIX) else "record"
    reads = {os.path.realpath(f) for f in inputs}
    for path in paths:
        if path != record and os.path.realpath(path) in reads:
            raise OutputError("is a file the stage reads (a layer, an IES profile or a ray "
                              "file): its output would replace its own input; rename it, or "
                              "write the outputs to another folder (--out)", str(path))
    existing = [p for p in paths if os.path.lexists(p)]
    for path in existing:
        if path.is_symlink() or not path.is_file():
            raise _not_ours(path, "is not a regular file")
        _readable(path)
    if not os.path.lexists(record):
        if existing:
            raise _not_ours(existing[0], f"exists, and no {what} of this stage "
                                         f"({record.name}) says lumitrace wrote it")
        return Claim()
    reference, files = read_record(record)
    if files is None:
        raise _not_ours(record, f"is not a {what} lumitrace wrote")
    notes = []
    if reference != stage_reference(stage_path, folder):
        recorded = folder / reference if reference else None
        if stage_path is None or recorded is None or \
                not _same_file(recorded, Path(stage_path)):
            if recorded is not None and recorded.exists() or stage_path is None:
                raise OutputError(f"holds the results of another stage, "
                                  f"{recorded or 'one with no file'}; write this stage's "
                                  "outputs to a folder of their own (--out)", str(record))
            notes.append(f"{record}: took over the results of {recorded}, which no longer "
                         "exists (a moved or renamed stage)")
    for path in existing:
        if path == record:
            continue
        digest = files.get(path.name)
        if digest is None:
            raise _not_ours(path, f"is not among the files {record.name} says lumitrace wrote")
        if file_digest(path) != digest:
            raise _not_ours(path, "changed since lumitrace wrote it")
    ours = set(p.name for p in paths)
    dropped = tuple(folder / name for name in files
                    if name in set(names) and name not in ours and (folder / name).is_file()
                    and file_digest(folder / name) == files[name])
    return Claim(dropped=dropped, notes=tuple(notes))


def recorded_files(layer: Path) -> dict[str, str]:
    """{file name: SHA-256} of the files a result layer records; empty where it records
    none (or is none lumitrace wrote)."""
    _, files = _recorded(Path(layer)) if os.path.lexists(layer) else (None, None)
    return files or {}


def vouched_bytes(layer: Path, path: Path) -> bytes | None:
    """The bytes of ``path``, an output in the result layer ``layer``'s folder, where the
    layer's ownership record vouches for them (the SHA-256 it recorded for that name) and
    ``path`` is a regular file, no symlink; None otherwise (changed, truncated, replaced,
    missing, or no record of it). The bytes hashed are the bytes returned."""
    path, layer = Path(path), Path(layer)
    if path.parent.absolute() != layer.parent.absolute():
        return None
    digest = recorded_files(layer).get(path.name)
    if digest is None:
        return None
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:
        return None
    with os.fdopen(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
            return None
        data = fh.read()
    return data if hashlib.sha256(data).hexdigest() == digest else None
