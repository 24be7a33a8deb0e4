"""Which run each published file of a stage belongs to: the run id in the EXR header, the
IES keyword ``[_LUMITRACE_RUN]``, the LDT report line and the result layer's metadata."""
from __future__ import annotations

import re
from pathlib import Path

from ..filenames import IES_SUFFIX, INTENSITY_SUFFIX, LDT_SUFFIX, RESULT_LAYER_SUFFIX
from .exr import read_exr_metadata
from .layer_text import custom_layer_data


#: A run id in the LDT's report line.
_LDT_RUN = re.compile(r"\brun ([0-9a-f]{16})\b")


def published_run_ids(folder: Path, name: str, layer_folder: Path | None = None
                      ) -> dict[str, str | None]:
    """Run id per output of stage ``name`` (None where the file is missing or says none);
    one complete set has one id everywhere."""
    folder = Path(folder)
    ids: dict[str, str | None] = {"exr": None, "ies": None, "ldt": None, "layer": None}
    exr = folder / f"{name}{INTENSITY_SUFFIX}"
    if exr.exists():
        ids["exr"] = (read_exr_metadata(exr) or {}).get("runId")
    ies = folder / f"{name}{IES_SUFFIX}"
    if ies.exists():
        for line in ies.read_text(errors="replace").splitlines():
            if line.startswith("[_LUMITRACE_RUN]") and len(line.split()) > 1:
                ids["ies"] = line.split()[1]
    ldt = folder / f"{name}{LDT_SUFFIX}"
    if ldt.exists():  # line 8, the report: "lumitrace run ID: NAME; ..." (or, before,
        # "lumitrace NAME run ID...")
        lines = ldt.read_text(encoding="latin-1").splitlines()
        found = _LDT_RUN.search(lines[7]) if len(lines) > 7 else None
        ids["ldt"] = found.group(1) if found else None
    layer = Path(layer_folder or folder) / f"{name}{RESULT_LAYER_SUFFIX}"
    if layer.exists():
        ids["layer"] = layer_data(layer).get("runId")
    return ids


def layer_data(layer: Path) -> dict[str, str]:
    """The ``lumitrace:*`` customLayerData of a result layer (run id, stage), without the
    ``lumitrace:`` prefix; empty for a layer that cannot be read or says nothing. Read
    from the text where it is plain (:func:`~.layer_text.custom_layer_data`), else by USD."""
    entries = custom_layer_data(layer)
    if entries is None:
        from pxr import Sdf, Tf

        try:
            data = Sdf.Layer.OpenAsAnonymous(str(layer), metadataOnly=True)
        except Tf.ErrorException:
            return {}
        if data is None:
            return {}
        entries = data.customLayerData
    return {k.split(":", 1)[1]: v for k, v in entries.items()
            if k.startswith("lumitrace:")}
