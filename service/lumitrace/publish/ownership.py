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

import json
import os
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
    layer_dir = layer.parent
    reads = {os.path.realpath(f) for f in inputs}
    for key, path in paths.items():
        if key != "result_layer" and os.path.realpath(path) in reads:
            raise OutputError("is a file the stage reads (a layer, an IES profile or a ray "
                              "file): its output would replace its own input; rename it, or "
                              "write the outputs to another folder (--out)", str(path))
    existing = [Path(p) for p in paths.values() if os.path.lexists(p)]
    for path in existing:
        if path.is_symlink() or not path.is_file():
            raise _not_ours(path, "is not a regular file")
        _readable(path)
    if not os.path.lexists(layer):
        if existing:
            raise _not_ours(existing[0], "exists, and no result layer of this stage "
                                         f"({layer.name}) says lumitrace wrote it")
        return Claim()
    reference, files = _recorded(layer)
    if files is None:
        raise _not_ours(layer, "is not a result layer lumitrace wrote")
    notes = []
    if reference != stage_reference(stage_path, layer_dir):
        recorded = layer_dir / reference if reference else None
        if stage_path is None or recorded is None or \
                not _same_file(recorded, Path(stage_path)):
            if recorded is not None and recorded.exists() or stage_path is None:
                raise OutputError(f"holds the results of another stage, "
                                  f"{recorded or 'one with no file'}; write this stage's "
                                  "outputs to a folder of their own (--out)", str(layer))
            notes.append(f"{layer}: took over the results of {recorded}, which no longer "
                         "exists (a moved or renamed stage)")
    for path in existing:
        if path == layer:
            continue
        digest = files.get(path.name)
        if digest is None:
            raise _not_ours(path, f"is not among the files {layer.name} says lumitrace wrote")
        if file_digest(path) != digest:
            raise _not_ours(path, "changed since lumitrace wrote it")
    ours = set(p.name for p in paths.values())
    names = output_names(layer.name[:-len(RESULT_LAYER_SUFFIX)])
    dropped = tuple(layer_dir / name for name in files
                    if name in names and name not in ours and (layer_dir / name).is_file()
                    and file_digest(layer_dir / name) == files[name])
    return Claim(dropped=dropped, notes=tuple(notes))
