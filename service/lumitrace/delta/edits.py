"""The edits layer: the accepted scene deltas of a stage, on disk beside it as
``NAME.lumitrace-edits.usda``, applied over the stage as a sublayer of its session layer.

Its opinions are the strongest of the composed stage (stronger than the root layer and its
sublayers), so an accepted delta always shows. The stage's own files are never edited by a
delta: :func:`merge_edits` folds the edits into the root layer when a user keeps them, and
:func:`discard_edits` removes the file when they do not.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path

from pxr import Sdf, Tf, Usd, UsdUtils

from ..atomic import atomic_path, fsync_path, write_text_durably
from ..errors import LumitraceWarning, StageError
from ..filenames import edits_layer_path
from ..stage.diagnostics import tf_message
from .lock import StageLock
from .usda_merge import merge_text

#: customLayerData key holding the last accepted revision.
REVISION_KEY = "lumitrace:revision"


def open_edits_layer(path: str | os.PathLike) -> Sdf.Layer:
    """The edits layer at ``path``, created empty (in memory only) when there is none."""
    path = Path(path).absolute()
    if path.exists():
        layer = _open_layer(path, "the edits layer")
        layer.Reload(force=True)
        return layer
    layer = Sdf.Layer.FindOrOpen(str(path)) or Sdf.Layer.CreateNew(str(path))
    if layer is None:
        raise StageError("cannot create the edits layer", str(path))
    layer.documentation = ("lumitrace scene deltas accepted by the service, applied over "
                           "the stage as its strongest layer")
    return layer


def _open_layer(path: Path, what: str) -> Sdf.Layer:
    """The layer file at ``path``; a :class:`StageError` naming it when it is not a
    readable USD layer (garbage, a folder, another format)."""
    if not path.is_file():
        raise StageError(f"cannot open {what}: not a regular file", str(path))
    try:
        layer = Sdf.Layer.FindOrOpen(str(path))
    except Tf.ErrorException as exc:
        raise StageError(f"cannot open {what}: {tf_message(exc)}", str(path)) from None
    if layer is None:
        raise StageError(f"cannot open {what}", str(path))
    return layer


def open_with_edits(stage_path: str | os.PathLike,
                    edits: str | os.PathLike | Sdf.Layer | None = None) -> Usd.Stage:
    """Open the stage with an edits layer (default: its own, when it exists) composed over
    it: a new anonymous session layer sublayers the edits layer, so that nothing the
    reader authors in the session layer ever reaches the edits."""
    stage_path = Path(stage_path).absolute()
    if edits is None:
        default = edits_layer_path(stage_path)
        edits = default if default.exists() else None
    session = Sdf.Layer.CreateAnonymous("lumitrace-session.usda")
    if edits is not None:
        layer = edits if isinstance(edits, Sdf.Layer) else open_edits_layer(edits)
        session.subLayerPaths.append(layer.identifier)
    root = _open_layer(stage_path, "the stage")
    try:
        stage = Usd.Stage.Open(root, session, Usd.Stage.LoadAll)
    except Tf.ErrorException as exc:
        raise StageError(f"cannot open as a USD stage: {tf_message(exc)}",
                         str(stage_path)) from None
    if stage is None:
        raise StageError("cannot open as a USD stage", str(stage_path))
    return stage


def revision_of(layer: Sdf.Layer) -> int:
    """The last revision recorded in the edits layer (0 for none)."""
    value = layer.customLayerData.get(REVISION_KEY, 0)
    return int(value) if isinstance(value, int) else 0


def save_edits(layer: Sdf.Layer, revision: int) -> None:
    """Record ``revision`` in the layer and write it to its file durably (atomic rename,
    file and folder flushed), so that a delta answered as accepted survives a crash."""
    data = dict(layer.customLayerData)
    data[REVISION_KEY] = int(revision)
    layer.customLayerData = data
    write_text_durably(layer.realPath or layer.identifier, layer.ExportToString())


def merge_edits(stage_path: str | os.PathLike,
                layer: str | os.PathLike | None = None) -> Path:
    """Fold the stage's edits layer (``layer``: another one, a fit's
    ``NAME.lumitrace-fit.usda``) into its root layer (the edits win), then remove the
    edits layer. Returns the root layer's path. Refused (:class:`LumitraceError` naming
    it) while a service holds the stage: it would write its edits back."""
    lock = StageLock.acquire(stage_path, "merging its edits")
    try:
        return _merge_edits(Path(stage_path).absolute(), layer)
    finally:
        lock.release()


def _merge_edits(stage_path: Path, layer: str | os.PathLike | None = None) -> Path:
    path = Path(layer).absolute() if layer is not None else edits_layer_path(stage_path)
    if not path.exists():
        raise StageError("no edits layer to merge", str(path))
    root = _open_layer(stage_path, "the stage")
    edits = _open_layer(path, "the edits layer")
    strong = Sdf.Layer.CreateAnonymous(".usda")
    strong.TransferContent(edits)
    UsdUtils.StitchLayers(strong, root)  # strong's opinions win, root's fill in
    # the root keeps its own layer metadata (sublayers, units, default prim, its data)
    strong.subLayerPaths[:] = list(root.subLayerPaths)
    strong.defaultPrim = root.defaultPrim
    strong.documentation = root.documentation
    strong.customLayerData = dict(root.customLayerData)
    for key in ("metersPerUnit", "upAxis", "startTimeCode", "endTimeCode",
                "timeCodesPerSecond"):
        if root.pseudoRoot.HasInfo(key):
            strong.pseudoRoot.SetInfo(key, root.pseudoRoot.GetInfo(key))
    why = _merge_as_text(stage_path, edits, strong)
    if not why:
        root.Reload(force=True)
        _discard_edits(stage_path, layer)
        return stage_path
    warnings.warn(f"{stage_path.name}: written again as USD writes it (its comments and "
                  f"formatting are not kept): {why}", LumitraceWarning, stacklevel=3)
    _keep_child_order(strong, root, Sdf.Path.absoluteRootPath)
    with atomic_path(stage_path) as tmp:  # keeps the suffix: .usda text, .usdc binary
        if not strong.Export(str(tmp)):
            raise StageError("cannot write the merged stage", str(stage_path))
        fsync_path(tmp)
    fsync_path(stage_path.parent)
    root.Reload(force=True)
    _discard_edits(stage_path, layer)
    return stage_path


def _merge_as_text(stage_path: Path, edits: Sdf.Layer, merged: Sdf.Layer) -> str:
    """Write a ``.usda`` stage merged with its edits as a text edit of the file (comments,
    formatting and prim order kept: :mod:`lumitrace.delta.usda_merge`) and return "";
    else write nothing and return why (the file is not ``.usda`` text, or the edit cannot
    be certain to equal ``merged``)."""
    if stage_path.suffix != ".usda":
        return "the stage is not a .usda file"
    try:
        text = stage_path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return "the stage is not UTF-8 text"
    if not text.startswith("#usda"):
        return "the stage is not USD text"
    edited, why = merge_text(text, edits, merged)
    if edited is None:
        return why
    write_text_durably(stage_path, edited)
    return ""


def _keep_child_order(layer: Sdf.Layer, like: Sdf.Layer, parent: Sdf.Path) -> None:
    """Order the children of ``parent`` in ``layer`` as in ``like`` (children only
    ``layer`` has come last): the order of parts is the stage's, not the edits'."""
    spec, ref = layer.GetObjectAtPath(parent), like.GetObjectAtPath(parent)
    if spec is None or ref is None:
        return
    have = [c.name for c in spec.nameChildren]
    want = [n for n in (c.name for c in ref.nameChildren) if n in have]
    want += [n for n in have if n not in want]
    if want != have:
        # a reorder statement: the composed order is the stage's
        if parent == Sdf.Path.absoluteRootPath:
            layer.rootPrimOrder[:] = want
        else:
            spec.nameChildrenOrder[:] = want
    for name in want:
        _keep_child_order(layer, like, parent.AppendChild(name))


def discard_edits(stage_path: str | os.PathLike,
                  layer: str | os.PathLike | None = None) -> bool:
    """Remove the stage's edits layer (``layer``: another one); True when there was one.
    Refused (:class:`LumitraceError` naming it) while a service holds the stage: it would
    write its edits back with the next delta."""
    lock = StageLock.acquire(stage_path, "discarding its edits")
    try:
        return _discard_edits(stage_path, layer)
    finally:
        lock.release()


def _discard_edits(stage_path: str | os.PathLike,
                   layer: str | os.PathLike | None = None) -> bool:
    path = Path(layer).absolute() if layer is not None else edits_layer_path(stage_path)
    try:
        path.unlink()
    except FileNotFoundError:
        return False
    layer = Sdf.Layer.Find(str(path))
    if layer is not None:
        layer.Clear()
    return True
