"""Applying a batch of scene deltas to the edits layer: all of them or none.

Every delta is authored in the edits layer through a USD edit target; every problem found
(a prim that is not there, a value of the wrong type, an asset path leaving the stage's
folder) is collected, and any problem restores the layer exactly as it was.
"""
from __future__ import annotations

import difflib
import math
import os
from pathlib import Path
from typing import Any, Callable

import numpy as np
from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdShade, UsdUtils

from ..errors import StageError
from ..schema import MATERIAL_RANGES, PROFILE_ATTRIBUTES
from ..stage.diagnostics import tf_message
from ..stage.luminaire_data import LUMINAIRE_DATA, luminaire_data_problem
from .assets import AssetRefused, check_asset, layer_problems, stage_variables
from .profile import write_profile_mesh
from .protocol import DeltaError, Problem


class _Bad(Exception):
    """One problem with one delta: ``why``, and where (a prim path and property)."""

    def __init__(self, why: str, where: str = ""):
        super().__init__(why)
        self.why = why
        self.where = where


def apply_deltas(stage: Usd.Stage, edits: Sdf.Layer, deltas: list[dict[str, Any]],
                 stage_dir: str | os.PathLike) -> None:
    """Author ``deltas`` (already schema-valid) in ``edits``, a layer of ``stage``'s session
    layer stack. Raises :class:`DeltaError` listing every problem, with ``edits`` restored;
    asset paths must resolve inside ``stage_dir``."""
    backup = edits.ExportToString()
    ctx = _Context(stage, edits, Path(stage_dir).resolve())
    problems: list[Problem] = []
    try:
        for i, delta in enumerate(deltas):
            try:
                with Usd.EditContext(stage, Usd.EditTarget(edits)):
                    _OPS[delta["op"]](ctx, delta)
            except _Bad as bad:
                where = f"/deltas/{i}" + (f" {bad.where}" if bad.where else "")
                problems.append(Problem(where, bad.why))
            except Tf.ErrorException as exc:
                problems.append(Problem(f"/deltas/{i} {delta.get('path', '')}".strip(),
                                        f"USD refused it: {tf_message(exc)}"))
    except BaseException:
        edits.ImportFromString(backup)
        raise
    if problems:
        edits.ImportFromString(backup)
        raise DeltaError(problems, 422)


class _Context:
    def __init__(self, stage: Usd.Stage, edits: Sdf.Layer, stage_dir: Path):
        self.stage = stage
        self.edits = edits
        self.stage_dir = stage_dir
        self.variables = stage_variables(stage)

    def prim(self, path: str) -> Usd.Prim:
        prim = self.stage.GetPrimAtPath(path)
        if not prim:
            raise _Bad("no prim at this path in the stage", path)
        return prim

    def asset(self, value: str, where: str) -> str:
        """An asset path that resolves inside the stage's folder, as written."""
        check_asset_path(value, self.stage_dir, where, self.variables)
        return value


def check_asset_path(value: str, stage_dir: Path, where: str = "",
                     variables: dict | None = None) -> None:
    """Refuse an asset path that is a URL or resolves outside ``stage_dir`` (see
    :mod:`lumitrace.delta.assets`)."""
    try:
        check_asset(value, stage_dir, variables or {})
    except AssetRefused as refused:
        raise _Bad(refused.why, where) from None


# ------------------------------------------------------------------------------------------
# Values
# ------------------------------------------------------------------------------------------

def _typed_value(value: Any, type_name: Sdf.ValueTypeName, ctx: _Context, where: str) -> Any:
    """The JSON ``value`` as the Python value USD takes for ``type_name``."""
    scalar = type_name.scalarType if type_name.isArray else type_name
    if scalar == Sdf.ValueTypeNames.Asset:
        items = value if type_name.isArray else [value]
        if not isinstance(items, list):
            raise _Bad(f"expects a list of asset paths, got {type(value).__name__}", where)
        paths = [Sdf.AssetPath(ctx.asset(v, where)) for v in items]
        return paths if type_name.isArray else paths[0]
    if scalar in (Sdf.ValueTypeNames.String, Sdf.ValueTypeNames.Token):
        ok = all(isinstance(v, str) for v in (value if type_name.isArray else [value]))
        if not ok or (type_name.isArray and not isinstance(value, list)):
            raise _Bad(f"expects {type_name} (text), got {json_type(value)}", where)
        return value
    if scalar == Sdf.ValueTypeNames.Bool:
        if not isinstance(value, bool):
            raise _Bad(f"expects a boolean, got {json_type(value)}", where)
        return value
    # numbers, vectors, matrices and their arrays: numbers only, finite
    if not type_name.isArray and scalar in _NUMBERS and not (
            isinstance(value, (int, float)) and not isinstance(value, bool)):
        raise _Bad(f"expects {type_name} (a number), got {json_type(value)}", where)
    if not _numeric(value):
        raise _Bad(f"expects {type_name} (numbers), got {json_type(value)}", where)
    if not _finite(value):
        raise _Bad("values must be finite numbers", where)
    converted = type_name.type.pythonClass
    if type_name.isArray and isinstance(value, list):
        fast = _float_array(value, type_name)
        return value if fast is None else fast
    if converted is not None and isinstance(value, list):
        try:
            return converted(*value) if len(value) in (2, 3, 4) and not isinstance(
                value[0], list) else converted(value)
        except (TypeError, Tf.ErrorException) as exc:
            raise _Bad(f"expects {type_name}: {exc}", where) from None
    return value


#: Element widths of the floating-point arrays a long value is set as through numpy: USD's
#: conversion of a Python list holds the interpreter throughout (200,000 points: 0.74 s,
#: through numpy 0.03 s), and the service answers nobody meanwhile.
_FLOAT_WIDTHS = {"float": 1, "double": 1, "GfVec2f": 2, "GfVec3f": 3, "GfVec4f": 4,
                 "GfVec2d": 2, "GfVec3d": 3, "GfVec4d": 4}
#: Values from which an array is set through numpy.
_NUMPY_FROM = 1024


def _float_array(value: list, type_name: Sdf.ValueTypeName) -> Any:
    """``value`` (numbers, checked finite) as the Vt array of a floating-point array
    ``type_name``, or None where it is short, of another type or not of the element's
    width (USD's own conversion then accepts or names it, as for any value)."""
    width = _FLOAT_WIDTHS.get(type_name.scalarType.type.typeName)
    if width is None or len(value) < _NUMPY_FROM:
        return None
    try:
        a = np.asarray(value, np.float64)
    except ValueError:  # ragged
        return None
    if a.shape != ((len(value),) if width == 1 else (len(value), width)):
        return None
    return type_name.type.pythonClass.FromNumpy(a)


_NUMBERS = {Sdf.ValueTypeNames.Float, Sdf.ValueTypeNames.Double, Sdf.ValueTypeNames.Half,
            Sdf.ValueTypeNames.Int, Sdf.ValueTypeNames.UInt, Sdf.ValueTypeNames.Int64,
            Sdf.ValueTypeNames.UInt64, Sdf.ValueTypeNames.UChar, Sdf.ValueTypeNames.TimeCode}


def json_type(value: Any) -> str:
    """The JSON name of a value's type (for messages)."""
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    return type(value).__name__


def _numeric(value: Any) -> bool:
    if isinstance(value, bool):
        return False
    if isinstance(value, (int, float)):
        return True
    return isinstance(value, list) and all(_numeric(v) for v in value)


def _finite(value: Any) -> bool:
    if isinstance(value, list):
        return all(_finite(v) for v in value)
    return math.isfinite(value)


def _attribute(ctx: _Context, prim: Usd.Prim, name: str, type_hint: str | None,
               where: str) -> Usd.Attribute:
    """The attribute ``name`` of ``prim``: existing, from an applied schema, from one of our
    API schemas (applied for it), or created with ``type_hint``."""
    attr = prim.GetAttribute(name)
    if attr and attr.GetTypeName():
        return attr
    api = _api_defining(name)
    if api is not None:
        prim.ApplyAPI(api)
        attr = prim.GetAttribute(name)
        if attr:
            return attr
    if prim.HasRelationship(name):
        raise _Bad("is a relationship, not an attribute (bind materials with 'bind')", where)
    if name.startswith("lumitrace:"):  # ours: a misspelt name would be traced as nothing
        raise _Bad(_unknown_lumitrace(name), where)
    if not type_hint:
        raise _Bad("the prim has no such attribute: give 'type' (an Sdf value type such as "
                   "float or color3f) to create one", where)
    type_name = Sdf.ValueTypeNames.Find(type_hint)
    if not type_name:
        raise _Bad(f"unknown value type {type_hint!r}", where)
    return prim.CreateAttribute(name, type_name, custom=True)


#: The API schemas whose attributes a delta may set (they are applied for it).
_DELTA_APIS = ("LumitraceMaterialAPI", "LumitraceEmitterAPI", "LumitraceLuminaireAPI",
               "LumitraceProfileAPI")


def _api_names(api: str) -> list[str]:
    """The attributes a delta may set of one of our API schemas (results left out)."""
    definition = Usd.SchemaRegistry().FindAppliedAPIPrimDefinition(api)
    names = definition.GetPropertyNames() if definition is not None else []
    return [n for n in names if not n.startswith("lumitrace:result:")]


def _api_defining(name: str) -> str | None:
    """The lumitrace API schema whose definition holds property ``name``, if any."""
    if not name.startswith("lumitrace:") or name.startswith("lumitrace:result:"):
        return None
    for api in _DELTA_APIS:
        if name in _api_names(api):
            return api
    return None


def _unknown_lumitrace(name: str) -> str:
    """Why a ``lumitrace:`` name no schema of ours defines is refused (even with a
    'type': the tracer would never read it), with the names nearest to it."""
    known = sorted({n for api in _DELTA_APIS for n in _api_names(api)})
    near = difflib.get_close_matches(name, known, n=3, cutoff=0.6)
    hint = f"did you mean {' or '.join(near)}? " if near else ""
    return (f"no lumitrace schema defines {name}: {hint}the attributes are "
            f"{', '.join(known)}")


def _set_value(ctx: _Context, prim: Usd.Prim, name: str, value: Any,
               type_hint: str | None) -> None:
    where = f"{prim.GetPath()}.{name}"
    if name.startswith("lumitrace:result:"):
        raise _Bad("result attributes are written by lumitrace, not by deltas", where)
    attr = _attribute(ctx, prim, name, type_hint, where)
    if attr.GetVariability() == Sdf.VariabilityUniform and name.startswith("xformOp"):
        raise _Bad("set transforms with 'transform'", where)
    typed = _typed_value(value, attr.GetTypeName(), ctx, where)
    problem = luminaire_data_problem(name, typed)  # what reaches the files, as the reader
    if problem is not None:
        raise _Bad(problem, where)
    bounds = MATERIAL_RANGES.get(name)
    if bounds is not None and isinstance(typed, (int, float)) and not isinstance(typed, bool):
        lo, hi = bounds
        if not lo <= typed <= hi:
            raise _Bad(f"must be in [{lo:g}, {hi:g}], got {typed!r}", where)
    if attr.GetTypeName() == Sdf.ValueTypeNames.Token:
        allowed = attr.GetMetadata("allowedTokens")
        if allowed and typed not in list(allowed):
            raise _Bad(f"must be one of {', '.join(map(str, allowed))}, got {typed!r}", where)
    try:
        ok = attr.Set(typed)
    except Tf.ErrorException as exc:
        raise _Bad(f"expects {attr.GetTypeName()}: {tf_message(exc)}", where) from None
    if not ok:
        raise _Bad(f"expects {attr.GetTypeName()}, got {json_type(value)}", where)


# ------------------------------------------------------------------------------------------
# The operations
# ------------------------------------------------------------------------------------------

def _op_set(ctx: _Context, d: dict) -> None:
    prim = ctx.prim(d["path"])
    _set_value(ctx, prim, d["property"], d["value"], d.get("type"))
    if d["property"] in PROFILE_ATTRIBUTES:
        _profile_mesh(prim, d["property"])


def _profile_mesh(prim: Usd.Prim, prop: str) -> None:
    """A profile changed: the mesh's points and faces made from it, in the edits layer
    (a bad profile is the delta's problem, naming the property)."""
    where = f"{prim.GetPath()}.{prop}"
    if not prim.IsA(UsdGeom.Mesh):
        raise _Bad(f"a profile makes a Mesh's points; this is a "
                   f"{prim.GetTypeName() or 'typeless'} prim", where)
    if not prim.GetAttribute(PROFILE_ATTRIBUTES[0]).HasAuthoredValue():
        return  # its points come with a later delta of the batch, or never
    try:
        write_profile_mesh(prim)
    except StageError as exc:
        raise _Bad(exc.message, f"{prim.GetPath()}.{exc.prop}" if exc.prop else where) \
            from None


def transform_matrix(d: dict) -> Gf.Matrix4d:
    """The local transform a 'transform' delta gives (USD's row-vector convention)."""
    if "matrix" in d:
        return Gf.Matrix4d(*[float(x) for row in d["matrix"] for x in row])
    s = d.get("scale", (1.0, 1.0, 1.0))
    r = d.get("rotate", (0.0, 0.0, 0.0))
    t = d.get("translate", (0.0, 0.0, 0.0))
    m = Gf.Matrix4d().SetScale(Gf.Vec3d(*map(float, s)))
    for axis, angle in zip(((1, 0, 0), (0, 1, 0), (0, 0, 1)), r):
        if angle:
            m = m * Gf.Matrix4d().SetRotate(Gf.Rotation(Gf.Vec3d(*axis), float(angle)))
    return m * Gf.Matrix4d().SetTranslate(Gf.Vec3d(*map(float, t)))


#: The op a 'transform' delta authors (its suffix keeps it apart from the stage's ops).
TRANSFORM_OP_SUFFIX = "lumitraceDelta"


def _op_transform(ctx: _Context, d: dict) -> None:
    prim = ctx.prim(d["path"])
    xf = UsdGeom.Xformable(prim)
    if not xf:
        raise _Bad(f"a {prim.GetTypeName() or 'typeless'} prim has no transform", d["path"])
    values = [float(x) for row in d.get("matrix", []) for x in row]
    values += [float(x) for k in ("translate", "rotate", "scale") for x in d.get(k, [])]
    if not all(math.isfinite(v) for v in values):
        raise _Bad("values must be finite numbers", d["path"])
    m = transform_matrix(d)
    if abs(m.GetDeterminant()) < 1e-300:
        raise _Bad("the transform is singular (a zero scale)", d["path"])
    xf.ClearXformOpOrder()
    op = xf.AddTransformOp(UsdGeom.XformOp.PrecisionDouble, TRANSFORM_OP_SUFFIX)
    op.Set(m)


def _op_bind(ctx: _Context, d: dict) -> None:
    prim = ctx.prim(d["path"])
    material = ctx.stage.GetPrimAtPath(d["material"])
    if not material:
        raise _Bad("no material prim at this path", d["material"])
    if not material.IsA(UsdShade.Material):
        raise _Bad(f"is a {material.GetTypeName() or 'typeless'} prim, not a Material",
                   d["material"])
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(UsdShade.Material(material))


def _op_add(ctx: _Context, d: dict) -> None:
    path = Sdf.Path(d["path"])
    if ctx.stage.GetPrimAtPath(path):
        raise _Bad("a prim already exists at this path", d["path"])
    parent = path.GetParentPath()
    if parent != Sdf.Path.absoluteRootPath and not ctx.stage.GetPrimAtPath(parent):
        raise _Bad("its parent prim does not exist", str(parent))
    prim = ctx.stage.DefinePrim(path, d["type"])
    registry = Usd.SchemaRegistry()
    for api in d.get("apiSchemas", []):
        if not registry.FindAppliedAPIPrimDefinition(api.split(":")[0]):
            raise _Bad(f"unknown applied API schema {api!r}", d["path"])
        prim.ApplyAPI(api)
    for name, value in d.get("properties", {}).items():
        _set_value(ctx, prim, name, value, None)
    if any(name in PROFILE_ATTRIBUTES for name in d.get("properties", {})):
        _profile_mesh(prim, PROFILE_ATTRIBUTES[0])


def _op_remove(ctx: _Context, d: dict) -> None:
    prim = ctx.prim(d["path"])
    path = prim.GetPath()
    if ctx.edits.GetPrimAtPath(path):
        ctx.stage.RemovePrim(path)  # what the deltas authored on it, or the prim they added
    if ctx.stage.GetPrimAtPath(path):  # defined by the stage's own layers: deactivate
        ctx.stage.GetPrimAtPath(path).SetActive(False)


def _op_active(ctx: _Context, d: dict) -> None:
    prim = ctx.prim(d["path"])
    if prim.IsPseudoRoot():
        raise _Bad("the pseudo-root cannot be deactivated", d["path"])
    prim.SetActive(bool(d["active"]))


def _op_variant(ctx: _Context, d: dict) -> None:
    prim = ctx.prim(d["path"])
    sets = prim.GetVariantSets()
    if not sets.HasVariantSet(d["set"]):
        have = ", ".join(sets.GetNames()) or "none"
        raise _Bad(f"no variant set {d['set']!r} (the prim has: {have})", d["path"])
    vset = sets.GetVariantSet(d["set"])
    names = vset.GetVariantNames()
    if d["selection"] not in names:
        raise _Bad(f"variant set {d['set']!r} has no variant {d['selection']!r} "
                   f"(it has: {', '.join(names)})", d["path"])
    vset.SetVariantSelection(d["selection"])


def _op_layer(ctx: _Context, d: dict) -> None:
    fragment = Sdf.Layer.CreateAnonymous(".usda")
    try:
        ok = fragment.ImportFromString(d["usda"])
    except Tf.ErrorException as exc:
        raise _Bad(f"not a valid USDA layer: {tf_message(exc)}") from None
    if not ok:
        raise _Bad("not a valid USDA layer")
    bad = layer_problems(fragment, ctx.stage_dir, ctx.variables) + _data_problems(fragment)
    if bad:  # checked before the fragment is composed: no file outside is ever opened
        raise _Bad("; ".join(f"{where}: {why}" for where, why in bad))
    merged = Sdf.Layer.CreateAnonymous(".usda")
    merged.TransferContent(fragment)
    UsdUtils.StitchLayers(merged, ctx.edits)  # the fragment's opinions win
    merged.customLayerData = dict(ctx.edits.customLayerData)
    ctx.edits.TransferContent(merged)


def _data_problems(layer: Sdf.Layer) -> list[tuple[str, str]]:
    """(where, why) of every value of the luminaire's own data in ``layer`` (defaults and
    time samples) that the stage reader would refuse (:mod:`~lumitrace.stage.luminaire_data`)."""
    found: list[tuple[str, str]] = []

    def visit(path: Sdf.Path) -> None:
        if not path.IsPropertyPath() or path.name not in LUMINAIRE_DATA:
            return
        spec = layer.GetAttributeAtPath(path)
        if not spec:
            return
        values = [spec.default] if spec.HasDefaultValue() else []
        values += [layer.QueryTimeSample(path, t) for t in layer.ListTimeSamplesForPath(path)]
        for value in values:
            problem = luminaire_data_problem(path.name, value)
            if problem is not None:
                found.append((f"{path.GetPrimPath()}.{path.name}", problem))
                return

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return found


_OPS: dict[str, Callable[[_Context, dict], None]] = {
    "set": _op_set, "transform": _op_transform, "bind": _op_bind, "add": _op_add,
    "remove": _op_remove, "active": _op_active, "variant": _op_variant, "layer": _op_layer,
}
