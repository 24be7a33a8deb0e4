"""USD's own diagnostics while a stage is read: warnings collected instead of printed,
composition errors judged (an error within the luminaire, a warning elsewhere), and pxr
error texts made readable."""
from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
import os
import re
import sys
from typing import Callable

from pxr import Pcp, Sdf, Usd

from ..errors import StageError
from ..filenames import RESULT_LAYER_SUFFIX
from .pxr_messages import NAMESPACE as _NAMESPACE, tf_message  # noqa: F401
from .validate import check_layer_file

#: The session layer USD adds to layer stacks in messages: ",@anon:0x...:NAME-session.usda@".
_ANON_LAYER = re.compile(r",@anon:[^@]*@")

#: Composition errors that leave the luminaire incomplete or undefined, with what to say.
_FATAL_COMPOSITION = {
    Pcp.ErrorType_InvalidAssetPath: "cannot open a referenced layer",
    Pcp.ErrorType_InvalidSublayerPath: "cannot open a sublayer",
    Pcp.ErrorType_ArcCycle: "composition cycle",
    Pcp.ErrorType_SublayerCycle: "sublayer cycle",
    Pcp.ErrorType_UnresolvedPrimPath: "reference to a prim that does not exist",
    Pcp.ErrorType_InvalidPrimPath: "reference to an invalid prim path",
    Pcp.ErrorType_ArcCapacityExceeded: "composition too deep",
    Pcp.ErrorType_ArcNamespaceDepthCapacityExceeded: "composition too deep",
    Pcp.ErrorType_IndexCapacityExceeded: "composition too large",
}
_SUBLAYER_ERRORS = {Pcp.ErrorType_InvalidSublayerPath, Pcp.ErrorType_SublayerCycle,
                    Pcp.ErrorType_InvalidSublayerOffset,
                    Pcp.ErrorType_InvalidSublayerOwnership}


class UsdDiagnostics:
    """While in use, USD's warnings and status messages are collected instead of printed
    (bad input must give one clear error, and nothing else, on stderr); the reader reports
    them as scene warnings, and composition errors itself."""

    def __enter__(self) -> "UsdDiagnostics":
        self._delegate = _usd_utils().CoalescingDiagnosticDelegate()
        return self

    def __exit__(self, *exc) -> None:
        self._delegate = None  # unregisters it

    def take(self) -> list[str]:
        """The messages collected so far (composition errors left out)."""
        notes = []
        for d in self._delegate.TakeUncoalescedDiagnostics():
            if d.sourceFunction.endswith("UsdStage::_ReportErrors"):
                continue
            notes.append(" ".join(_NAMESPACE.sub("", d.commentary).split())[:300])
        return notes


@functools.lru_cache(maxsize=1)
def _usd_utils():
    """UsdUtils' compiled module, loaded alone: the reader needs its diagnostic delegate,
    and the package's Python helpers (usdz packages, Sdr schema tools) load zipfile, UsdUI
    and Sdr, 8 ms of every command. Registered under its own name, so a later ``import
    pxr.UsdUtils`` takes it as it is; where it cannot be loaded so, the package is."""
    name = "pxr.UsdUtils._usdUtils"
    if name not in sys.modules:
        try:
            import pxr

            folder = os.path.join(os.path.dirname(pxr.__file__), "UsdUtils")
            path = next(p for p in (os.path.join(folder, "_usdUtils" + s)
                                    for s in importlib.machinery.EXTENSION_SUFFIXES)
                        if os.path.exists(p))
            spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            sys.modules[name] = module
        except Exception:  # another layout of the package: load it whole
            from pxr import UsdUtils

            return UsdUtils
    return sys.modules[name]


def check_composition(stage: Usd.Stage, root: Usd.Prim, layer_where: str,
                      warn: Callable[[str], None]) -> None:
    """Composition errors that leave the luminaire incomplete (a missing layer, a cycle,
    a reference to no prim) are bad input; elsewhere in the stage they are warnings, as
    is a missing result layer of ours (the next run writes it again)."""
    root_path = root.GetPath()
    for error in stage.GetCompositionErrors():
        message = _ANON_LAYER.sub("", tf_message(error))
        site = error.rootSite.path
        what = _FATAL_COMPOSITION.get(error.errorType)
        sublayer = error.errorType in _SUBLAYER_ERRORS
        where = layer_where if sublayer or site.IsAbsoluteRootPath() else str(site)
        ours = sublayer and RESULT_LAYER_SUFFIX in message
        inside = (site.IsAbsoluteRootPath() or site.HasPrefix(root_path)
                  or root_path.HasPrefix(site))
        if what is not None and inside and not ours:
            prop = "subLayers" if sublayer else _arc_property(message)
            raise StageError(f"{what}: {message}", where, prop)
        warn(f"{where}: composition error: {message}")


def check_sublayers(stage: Usd.Stage, layer_where: str) -> None:
    """A sublayer that cannot be opened (missing, unparsable, a cycle) is bad input, unless
    it is a result layer of ours (the next run writes it again)."""
    for error in stage.GetCompositionErrors():
        what = _FATAL_COMPOSITION.get(error.errorType)
        if what is None or error.errorType not in _SUBLAYER_ERRORS:
            continue
        message = _ANON_LAYER.sub("", tf_message(error))
        if RESULT_LAYER_SUFFIX not in message:
            _check_sublayer_files(stage.GetRootLayer())  # names a bad file's line if it can
            raise StageError(f"{what}: {message}", layer_where, "subLayers")


def _check_sublayer_files(layer: Sdf.Layer) -> None:
    """Run the file checks of :func:`validate.check_layer_file` on the sublayers of
    ``layer`` that exist on disk, so that a parse failure is reported with its line."""
    for sub in layer.subLayerPaths:
        path = layer.ComputeAbsolutePath(sub)
        if path and os.path.isfile(path):
            check_layer_file(path)


def _arc_property(message: str) -> str:
    """The composition arc a Pcp message is about, as the metadata field that authors it."""
    text = message.lower()
    for word, field_name in (("payload", "payload"), ("inherit", "inherits"),
                             ("specializ", "specializes"), ("variant", "variantSets")):
        if word in text:
            return field_name
    return "references"
