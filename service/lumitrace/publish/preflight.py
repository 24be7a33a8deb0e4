"""What a command checks before a long trace: the stage is a file, its output folder can be
written, and its root layer holds no result opinions that would hide the new results."""
from __future__ import annotations

import os
from pathlib import Path

from ..errors import LumitraceError


def refuse_hidden_results(stage: Path) -> None:
    """Stop before tracing when the stage's root layer, which is stronger than the result
    layer sublayered into it, holds result opinions (a stage flattened with its results):
    the new results would compose hidden under them. Reads the root layer alone (no
    composition: a stage with other problems is the reader's to report)."""
    from .publish.check import may_hold_results, result_opinion_prims

    if not may_hold_results(stage):
        return
    from pxr import Sdf

    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(stage), metadataOnly=False)
    except Exception:  # noqa: BLE001 - the stage reader reports what is wrong, clearly
        return
    prims = result_opinion_prims(layer) if layer is not None else []
    if prims:
        raise LumitraceError(
            f"holds lumitrace:result:* opinions on {prims[0]} that are stronger than the "
            "result layer (left by flattening a stage with results?): the new results "
            "would be hidden under them. Trace with --replace-results to remove them, or "
            "with --no-sublayer",
            str(stage))


def preflight(stage: Path, out: Path | None, stage_folder_written: bool = False) -> None:
    """What can be checked before a long trace: the stage is a regular file, the output
    folder (``out``, else the stage's) exists or can be made, and can be written to, as
    can the stage's own folder where ``stage_folder_written`` (the service's edits
    layer lives there)."""
    import stat as st

    try:
        mode = os.stat(stage).st_mode
    except FileNotFoundError:
        raise LumitraceError("stage file not found", str(stage)) from None
    except OSError as exc:
        raise LumitraceError(f"cannot open the stage: {exc.strerror}", str(stage)) from None
    if not st.S_ISREG(mode):
        raise LumitraceError("the stage is not a regular file", str(stage))
    folders = [out.absolute() if out is not None else stage.absolute().parent]
    if stage_folder_written and out is not None:
        folders.append(stage.absolute().parent)
    for folder in folders:
        _writable_folder(folder, out is None)


def _writable_folder(folder: Path, hint_out: bool) -> None:
    """Make ``folder`` if missing and prove it writable by writing in it."""
    if folder.exists() and not folder.is_dir():
        raise LumitraceError("the output folder is a file, not a folder", str(folder))
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LumitraceError(f"cannot create the output folder: {exc.strerror}",
                             str(folder)) from None
    try:  # a real write: permissions, read-only mounts and ACLs all answer it
        import tempfile

        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        hint = "" if not hint_out else \
            " (results go to the stage's folder unless --out names another)"
        raise LumitraceError(f"the output folder is not writable: {exc.strerror}{hint}",
                             str(folder)) from None
