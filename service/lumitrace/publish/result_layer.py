"""The result layer: the traced result written back into the stage.

For a stage ``NAME.usda`` the result goes into ``NAME.lumitrace.usda`` beside it: an ``over``
of the luminaire prim with ``LumitraceLuminaireAPI`` applied and the
``lumitrace:result:*`` attributes. The result layer is then sublayered into the stage's
root layer, once: the first run inserts ``./NAME.lumitrace.usda`` at the front of the root
layer's ``subLayers``; later runs only rewrite the result layer.

Both files are written atomically (a temporary file in the same folder, then a rename), the
result layer first, so a reader never sees a sublayer entry without its layer nor a
half-written file. When the root layer is text (``.usda``) the entry is inserted into the
file's text, so comments and formatting survive; the edit is checked against an Sdf
round trip and, should the two disagree, the Sdf export is written instead. Binary roots
(``.usdc``, crate ``.usd``) are exported by Sdf in their own format. A ``.usdz`` package
or a root layer that cannot be written is left alone: the result layer is still written and
a :class:`ResultLayerWarning` says that it has to be sublayered by hand.
"""
from __future__ import annotations

import math
import numbers
import os
from pathlib import Path
from typing import Any, Mapping

from ..atomic import UMASK, atomic_path
from ..errors import OutputError
from ..filenames import result_layer_path
from ..schema import RESULT_KINDS, RESULT_PREFIX
from . import layer_text
from .layer_text import PHOTOMETRIC_LIGHT, REPRESENTATION  # noqa: F401
from .sublayer import ResultLayerWarning, file_mode, reload_if_open, sublayer_into_root
from ..stage.pxr_messages import tf_message

__all__ = ["ResultLayerWarning", "ResultValueError", "RESULT_KINDS", "convert_results",
           "result_layer_path", "write_result_layer"]

_NON_NEGATIVE = {"photons", "iterations", "resolution"}
_INT_RANGE = {"int": (-2 ** 31, 2 ** 31 - 1), "int64": (-2 ** 63, 2 ** 63 - 1)}


class ResultValueError(OutputError, ValueError):
    """A result value of the wrong type or out of range, an unknown key or a bad prim
    path, found before anything is written."""


def write_result_layer(stage_path: str | os.PathLike, luminaire_path: str | None,
                       results: Mapping[str, Any], light: Mapping[str, Any] | None = None
                       ) -> Path:
    """Write the result layer beside the stage and sublayer it into the stage once.

    Parameters
    ----------
    stage_path : path
        The stage's root layer (``.usda``, ``.usdc``, ``.usd`` or ``.usdz``); it must exist.
    luminaire_path : str or None
        Absolute path of the luminaire prim (the stage's default prim); ``None`` reads the
        root layer's ``defaultPrim``.
    results : mapping
        Attribute suffix -> value, with the keys of :data:`RESULT_KINDS`; any subset
        may be given, and the layer holds exactly the given ones (each call rewrites it).
        Assets (``intensityMap``, ``iesFile``, ``ldtFile``) are file paths: relative ones are
        taken as relative to the stage's folder (where the result layer lives), absolute ones
        are made relative to it. ``photons`` (int64), ``iterations``, ``resolution``,
        ``seed`` (int) take integers (counts must be >= 0); ``elapsedSeconds`` (s),
        ``relativeError``, ``luminousFlux`` (lm), ``lightOutputRatio``, ``threshold``
        take real numbers (stored as double; inf and nan are kept as such);
        ``converged`` takes a bool, ``inputHash`` a string.
    light : mapping, optional
        The IES-shaped UsdLux light standing in for the luminaire, authored in the
        ``photometric`` variant of the ``lumitraceRepresentation`` variant set (see
        :func:`~lumitrace.publish.layer_text.photometric_variant` for its keys); missing
        keys raise ``ValueError``.

    Returns
    -------
    Path
        The result layer ``NAME.lumitrace.usda``.

    Raises
    ------
    ValueError
        An unknown key, a value of the wrong type or out of range, a bad prim path. Raised
        before anything is written.
    OutputError
        A missing stage or a file that cannot be written; files already on disk are left
        as they were.
    """
    stage = Path(stage_path).absolute()
    layer_path = result_layer_path(stage)
    text = result_layer_text(stage, luminaire_path, results, light, layer_path.parent)
    write_layer_file(stage, layer_path, text)
    sublayer_into_root(stage, layer_path)
    return layer_path


def result_layer_text(stage: Path | None, luminaire_path: str | None,
                      results: Mapping[str, Any], light: Mapping[str, Any] | None,
                      layer_dir: Path, layer_data: Mapping[str, str] | None = None,
                      units: tuple[str, float] | None = None) -> str:
    """The result layer as usda text (see :func:`write_result_layer`); ``layer_data`` goes
    into its customLayerData (the run id and stage it belongs to); ``units`` (up axis,
    metres per unit) are the stage's, so that the layer opened on its own is a valid stage
    (with its defaultPrim too). ``stage`` is None for a stage with no file of its own
    (``luminaire_path`` is then required). Checks every value and raises
    :class:`ResultValueError` before anything is written."""
    if stage is not None and not stage.is_file():
        raise OutputError("no such stage file", str(stage))
    if stage is None and not luminaire_path:
        raise ResultValueError("a stage with no file needs the luminaire's prim path")
    values = convert_results(results, layer_dir)
    if light is not None:
        missing = sorted({"ies", "flux", "radius", "position"} - set(light))
        if missing:
            raise ResultValueError(f"the result light needs {', '.join(missing)}")
        # every asset path of the layer written alike: relative, ./ or ../ first
        light = {**light, "ies": _relative_asset(light["ies"], layer_dir, "the light's IES")}
    prim_path = _luminaire_path(stage, luminaire_path)
    documentation = (f"lumitrace result for {stage.name}, sublayered into it; rewritten "
                     "by every run." if stage is not None else
                     f"lumitrace result for the luminaire {prim_path} of a stage with no "
                     "file of its own; rewritten by every run.")
    return layer_text.result_layer_text(prim_path, values, light, layer_data, units,
                                        documentation)


def layer_mode(stage: Path | None, layer: Path | None) -> int:
    """The file mode of a result layer: the layer's it replaces, else the stage's (whoever
    reads the stage reads its results), never executable. A mode that does not let its
    owner read and write is no model (a stage made unreadable while a delta came, a layer
    an earlier version left so): lumitrace reads back every layer it wrote, and one it
    cannot read would refuse every later run. An ordinary file's mode (0666 less the
    umask) where neither is a model."""
    for model in (layer, stage):
        mode = file_mode(model, None) if model is not None else None
        if mode is not None and mode & 0o600 == 0o600:
            return mode & 0o666
    return 0o666 & ~UMASK


def write_layer_file(stage: Path | None, path: Path, text: str,
                     replaces: Path | None = None) -> None:
    """Write layer text atomically with the mode of :func:`layer_mode`: that of the layer
    at ``replaces`` (default ``path``: a layer staged elsewhere names the one it will
    replace), or the stage's."""
    mode = layer_mode(stage, replaces if replaces is not None else path)
    try:
        with atomic_path(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
            os.chmod(tmp, mode)
    except OSError as exc:
        raise OutputError(f"cannot write the result layer: {exc}", str(path)) from exc
    reload_if_open(path)


# ------------------------------------------------------------------------------------------
# Values
# ------------------------------------------------------------------------------------------


def convert_results(results: Mapping[str, Any], layer_dir: str | os.PathLike) -> dict:
    """Check and convert result values to the Python types of their Sdf value types
    (an asset becomes its path relative to ``layer_dir``). Raises ``ValueError``."""
    if not isinstance(results, Mapping):
        raise ResultValueError(f"results must be a mapping, got {type(results).__name__}")
    unknown = sorted(set(results) - set(RESULT_KINDS))
    if unknown:
        raise ResultValueError(f"unknown result attribute(s) {', '.join(map(repr, unknown))}; "
                         f"known: {', '.join(RESULT_KINDS)}")
    out = {}
    for key, kind in RESULT_KINDS.items():   # fixed order: a deterministic layer
        if key not in results:
            continue
        value = results[key]
        name = RESULT_PREFIX + key
        if kind == "asset":
            out[key] = _relative_asset(value, Path(layer_dir), name)
        elif kind in _INT_RANGE:
            out[key] = _as_int(value, kind, name, non_negative=key in _NON_NEGATIVE)
        elif kind == "double":
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise ResultValueError(f"{name}: expected a real number, got {value!r}")
            out[key] = float(value)
        elif kind == "bool":
            if type(value).__name__ not in ("bool", "bool_"):
                raise ResultValueError(f"{name}: expected a bool, got {value!r}")
            out[key] = bool(value)
        else:  # string
            if not isinstance(value, str):
                raise ResultValueError(f"{name}: expected a string, got {value!r}")
            out[key] = value
    return out


def _as_int(value: Any, kind: str, name: str, non_negative: bool) -> int:
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        raise ResultValueError(f"{name}: expected an integer, got {value!r}")
    if isinstance(value, numbers.Integral):
        v = int(value)
    elif isinstance(value, numbers.Real) and math.isfinite(value) and float(value).is_integer():
        v = int(value)
    else:
        raise ResultValueError(f"{name}: expected an integer, got {value!r}")
    lo, hi = _INT_RANGE[kind]
    if non_negative:
        lo = 0
    if not lo <= v <= hi:
        raise ResultValueError(f"{name}: {v} is out of range [{lo}, {hi}] for {kind}")
    return v


def _relative_asset(value: Any, layer_dir: Path, name: str) -> str:
    if type(value).__name__ == "AssetPath":  # an Sdf.AssetPath, taken without loading USD
        value = value.path
    if not isinstance(value, (str, os.PathLike)) or not os.fspath(value):
        raise ResultValueError(f"{name}: expected a file path, got {value!r}")
    path = os.fspath(value)
    if os.path.isabs(path):
        try:
            path = os.path.relpath(path, layer_dir)
        except ValueError:       # another drive: keep it absolute
            return Path(path).as_posix()
    rel = Path(path).as_posix()
    if not rel.startswith(("./", "../")):
        rel = "./" + rel
    return rel


# ------------------------------------------------------------------------------------------
# Layers
# ------------------------------------------------------------------------------------------


def _luminaire_path(stage: Path, luminaire_path: str | None) -> str:
    """The luminaire's absolute prim path: the one given, else the stage's defaultPrim."""
    if luminaire_path is None or str(luminaire_path) == "":
        layer = _open_copy(stage, metadata_only=True)
        if not layer.defaultPrim:
            raise ResultValueError(f"{stage}: no luminaire prim given and the stage has no "
                             "defaultPrim")
        luminaire_path = "/" + layer.defaultPrim
    path = str(luminaire_path)
    names = path.split("/")
    if len(names) < 2 or names[0] != "" or not all(n.isidentifier() for n in names[1:]):
        raise ResultValueError(f"luminaire path must be an absolute prim path, got "
                         f"{str(luminaire_path)!r}")
    return path


def _open_copy(path: Path, metadata_only: bool = False):
    """A private, anonymous copy of the layer as it is on disk (never the registry's
    instance, which may hold unsaved edits of whoever else has the stage open)."""
    from pxr import Sdf, Tf

    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(path), metadataOnly=metadata_only)
    except Tf.ErrorException as exc:
        raise OutputError(f"cannot read the stage's root layer: {tf_message(exc)}",
                          str(path)) from exc
    if layer is None:
        raise OutputError("cannot read the stage's root layer", str(path))
    return layer


