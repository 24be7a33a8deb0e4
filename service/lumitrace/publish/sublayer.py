"""Sublayering the result layer into the stage's root layer, once, without losing edits."""
from __future__ import annotations

import os
import stat
import warnings
from pathlib import Path

from ..atomic import atomic_path
from ..errors import OutputError, OutputWarning
from .usda_text import insert_sublayer_text


class ResultLayerWarning(OutputWarning):
    """The result layer was written but could not be sublayered into the stage."""


def file_mode(path: Path) -> int:
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except OSError:
        return 0o644


def _resolves_to(entry: str, root_dir: Path, target: Path) -> bool:
    if "://" in entry or entry.startswith("@"):
        return False
    candidate = Path(entry) if os.path.isabs(entry) else root_dir / entry
    return os.path.normcase(os.path.normpath(candidate)) == \
        os.path.normcase(os.path.normpath(target))


def _warn(message: str) -> None:
    warnings.warn(message, ResultLayerWarning, stacklevel=4)  # the caller


def sublayer_into_root(stage: Path, layer_path: Path, root) -> None:
    """Put ``./NAME.lumitrace.usda`` first in the stage root layer's subLayers, once."""
    entry = "./" + layer_path.name
    suffix = stage.suffix.lower()
    if root is None:
        _warn(f"{stage}: a .usdz package is not modified; add {entry} to its subLayers "
              f"(or open {layer_path.name} over it) to see the result in the stage")
        return
    if any(_resolves_to(p, stage.parent, layer_path) for p in root.subLayerPaths):
        _sync_open_root(stage, entry, layer_path)
        return
    if not (os.access(stage, os.W_OK) and os.access(stage.parent, os.W_OK)):
        _warn(f"{stage}: the root layer is not writable; the result is in "
              f"{layer_path.name} but is not sublayered into the stage")
        return

    data = stage.read_bytes()
    new_text = None
    if data.startswith(b"#usda"):
        new_text = insert_sublayer_text(data.decode("utf-8"), entry, root)
    mode = file_mode(stage)
    target = Path(os.path.realpath(stage))   # replace the file, not a symlink to it
    try:
        with atomic_path(target) as tmp:
            if new_text is not None:
                tmp.write_bytes(new_text.encode("utf-8"))
            else:
                root.subLayerPaths.insert(0, entry)
                args = {}
                if suffix == ".usd":   # keep the underlying format of a .usd file
                    args["format"] = "usda" if data.startswith(b"#usda") else "usdc"
                if not root.Export(str(tmp), args=args):
                    raise OSError("Sdf could not export the root layer")
            os.chmod(tmp, mode)
    except OSError as exc:
        raise OutputError(f"cannot sublayer the result layer into the stage: {exc}",
                          str(stage)) from exc
    _sync_open_root(stage, entry, layer_path)


def reload_if_open(path: Path) -> None:
    """Reload a layer this process has open, so its stages see the new file."""
    from pxr import Sdf

    layer = Sdf.Layer.Find(str(path))
    if layer is not None:
        layer.Reload(force=True)


def _sync_open_root(stage: Path, entry: str, layer_path: Path) -> None:
    """Bring an open instance of the root layer in line with the file: reload it when it
    has no unsaved edits, otherwise add the sublayer entry in memory (keeping the edits)."""
    from pxr import Sdf

    layer = Sdf.Layer.Find(str(stage))
    if layer is None:
        return
    if any(_resolves_to(p, stage.parent, layer_path) for p in layer.subLayerPaths):
        return
    if layer.dirty:
        layer.subLayerPaths.insert(0, entry)
    else:
        layer.Reload(force=True)


