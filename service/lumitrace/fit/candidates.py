"""Candidates as layers: each candidate's values authored in one layer over the stage.

The stage is opened once with a session layer whose only sublayer is the fit's layer; a
candidate clears that layer, authors its values in it (a mesh whose profile changes gets
its points made from the profile there too) and reads the scene. The stage's own files are
never written. The best candidate's layer is saved as ``NAME.lumitrace-fit.usda``: ``trace
--edits`` composes it over the stage, ``edits merge --layer`` keeps it.
"""
from __future__ import annotations

import os
from collections import defaultdict
from pathlib import Path
from typing import Sequence

import numpy as np
from pxr import Sdf, Tf, Usd, Vt

from ..atomic import write_text_durably
from ..delta.profile import write_profile_mesh
from ..errors import StageError
from ..filenames import stage_name
from ..scene import Scene
from ..stage.diagnostics import tf_message
from ..stage.reader import scene_from_stage
from ..stage.reuse import ReadCache
from ..stage.validate import check_layer_file
from .parameters import Parameter

#: Suffix of the layer a fit writes its best in: ``NAME.lumitrace-fit.usda``.
FIT_LAYER_SUFFIX = ".lumitrace-fit.usda"
#: customLayerData key of the fit's record in its layer.
FIT_KEY = "lumitrace:fit"


def fit_layer_name(stage_path: str | os.PathLike) -> str:
    return stage_name(stage_path) + FIT_LAYER_SUFFIX


class CandidateStage:
    """The stage opened once, with a layer over it that holds one candidate at a time
    (over ``edits``, an edits layer's file, where given: the live view's session)."""

    def __init__(self, stage_path: str | os.PathLike, luminaire: str | None = None,
                 edits: str | os.PathLike | None = None):
        self.path = Path(stage_path).absolute()
        if not self.path.is_file():
            raise StageError("stage file not found" if not self.path.exists() else
                             "the stage is not a regular file", str(self.path))
        check_layer_file(self.path)
        self.luminaire = luminaire
        self.layer = Sdf.Layer.CreateAnonymous("lumitrace-fit.usda")
        session = Sdf.Layer.CreateAnonymous("lumitrace-fit-session.usda")
        session.subLayerPaths.append(self.layer.identifier)
        if edits is not None:
            check_layer_file(Path(edits))
            session.subLayerPaths.append(str(Path(edits).absolute()))
        try:
            root = Sdf.Layer.FindOrOpen(str(self.path))
            self.stage = Usd.Stage.Open(root, session, Usd.Stage.LoadAll) if root else None
        except Tf.ErrorException as exc:
            raise StageError(f"cannot open as a USD stage: {tf_message(exc)}",
                             str(self.path)) from None
        if self.stage is None:
            raise StageError("cannot open as a USD stage", str(self.path))
        self.cache = ReadCache()

    def author(self, params: Sequence[Parameter], values: Sequence) -> None:
        """Clear the fit's layer and author ``values`` (one per parameter) in it."""
        self.layer.Clear()
        groups: dict[tuple, list[tuple[Parameter, object]]] = defaultdict(list)
        for p, v in zip(params, values):
            groups[p.attribute].append((p, v))
        with Usd.EditContext(self.stage, Usd.EditTarget(self.layer)):
            profiles = []
            for (path, _), items in groups.items():
                prim = self.stage.GetPrimAtPath(path)
                first = items[0][0]
                if first.variant_set is not None:
                    prim.GetVariantSets().GetVariantSet(first.variant_set) \
                        .SetVariantSelection(str(items[0][1]))
                    continue
                attr = prim.GetAttribute(first.prop)
                attr.Set(_with_elements(attr, items))
                if first.profile:
                    profiles.append(prim)
            for prim in profiles:
                write_profile_mesh(prim)

    def scene(self, params: Sequence[Parameter], values: Sequence) -> Scene:
        """The scene of a candidate (see :meth:`author`)."""
        self.author(params, values)
        return scene_from_stage(self.stage, self.luminaire, cache=self.cache)

    def save(self, params: Sequence[Parameter], values: Sequence, out_dir: Path,
             record: dict) -> Path:
        """Write ``values`` as the fit's layer ``NAME.lumitrace-fit.usda`` in ``out_dir``
        (atomic), with ``record`` (what the fit found) in its customLayerData."""
        self.author(params, values)
        layer = Sdf.Layer.CreateAnonymous(".usda")
        layer.TransferContent(self.layer)
        layer.documentation = (f"lumitrace fit of {self.path.name}: the best values found, "
                               "composed over the stage as its strongest layer "
                               "(lumitrace trace --edits, lumitrace edits merge --layer)")
        layer.customLayerData = {FIT_KEY: _usd_dict(record)}
        path = Path(out_dir).absolute() / fit_layer_name(self.path)
        write_text_durably(path, layer.ExportToString())
        return path


def _with_elements(attr: Usd.Attribute, items: list[tuple[Parameter, object]]):
    """The attribute's value with the parameters' elements set (a whole-attribute
    parameter: the value itself, as its type)."""
    value = attr.Get()
    type_name = attr.GetTypeName()
    if not items[0][0].index:
        v = items[0][1]
        return int(v) if items[0][0].discrete else float(v)
    array = np.array(value, dtype=np.float64)
    for p, v in items:
        array[p.index] = v
    cls = type_name.type.pythonClass
    if type_name.isArray:
        return cls.FromNumpy(array.astype(np.float32 if _single(type_name) else np.float64)
                             if not items[0][0].discrete else array.astype(np.int32))
    return cls(*[(int(x) if items[0][0].discrete else float(x)) for x in array.ravel()])


def _single(type_name: Sdf.ValueTypeName) -> bool:
    name = str(type_name.scalarType)
    return name.endswith("f") or name.startswith("float") or name.endswith("h") or \
        name.startswith("half")


def _usd_dict(record: dict) -> dict:
    """``record`` with values USD's customLayerData holds (numbers, text, lists of them)."""
    out = {}
    for k, v in record.items():
        if isinstance(v, dict):
            out[k] = _usd_dict(v)
        elif isinstance(v, (bool, int, float, str)):
            out[k] = v
        elif isinstance(v, (list, tuple)) and all(isinstance(x, (int, float)) and
                                                  not isinstance(x, bool) for x in v):
            out[k] = Vt.DoubleArray([float(x) for x in v])
        elif v is not None:
            out[k] = str(v)
    return out
