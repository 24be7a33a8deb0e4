"""Write what changed in Blender as opinions over the original stage, on its own prim
paths: never a flattened rewrite, so the stage's composition (sublayers, references,
variants, the result layer) stays as it was.

Two forms (``mode``):

- ``stage``: a new root layer that sublayers the original (by a relative path where one
  exists) and holds the edits, with the original's defaultPrim, metersPerUnit and upAxis:
  ``lumitrace trace EXPORT.usda`` traces the edited luminaire.
- ``edits``: the edits alone, for ``lumitrace trace STAGE --edits EXPORT.usda`` or for a
  pipeline that sublayers it where it likes.

The file is written atomically (a temporary file in the same folder, then a rename): a
reader never sees half an export, and a refused export leaves the old file as it was.
"""
from __future__ import annotations

import dataclasses
import os
import tempfile

from . import state
from .usd import pxr_modules

#: The xformOp an export authors (its suffix keeps it apart from the stage's own ops, so
#: no attribute of another type is overridden).
TRANSFORM_OP = "xformOp:transform:blender"
MODES = ("stage", "edits")


def edits_since_import(entry: dict) -> list[state.Edit]:
    """The edits from the imported state of stage ``entry`` to what Blender shows now."""
    return state.edits(entry, state.recorded_state(entry), state.state_of_stage(entry))


def export_stage(entry: dict, filepath: str, mode: str = "stage") -> dict:
    """Write the changes made in Blender to the stage ``entry`` to ``filepath``; returns
    ``{"file", "edits", "mode"}``. Raises :class:`state.ExportError` (nothing written)
    for a change lumitrace could not read."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    target = os.path.abspath(filepath)
    if os.path.realpath(target) == entry["file"]:
        raise state.ExportError("would overwrite the stage it is made over; choose another "
                                "file", target)
    changes = edits_since_import(entry)
    layer = edits_layer(entry, changes, original=entry["file"] if mode == "stage" else None,
                        anchor=os.path.dirname(target))
    write_text(target, layer.ExportToString())
    return {"file": target, "edits": len(changes), "mode": mode}


def edits_layer(entry: dict, changes: list[state.Edit], original: str | None = None,
                anchor: str | None = None):
    """An anonymous Sdf layer holding ``changes`` as opinions (``over`` specs, ``def``
    for new prims); with ``original``, sublayering it (relative to ``anchor``) and
    carrying its stage metadata."""
    Usd, Sdf, UsdGeom, UsdLux, UsdShade, Gf, Vt = pxr_modules()
    layer = Sdf.Layer.CreateAnonymous(".usda")
    if original is not None:
        layer.subLayerPaths.append(layer_path(original, anchor))
        if entry.get("defaultPrim"):
            layer.defaultPrim = entry["defaultPrim"]
        layer.pseudoRoot.SetInfo("metersPerUnit", float(entry["metersPerUnit"]))
        layer.pseudoRoot.SetInfo("upAxis", entry["upAxis"])
    layer.documentation = ("Edits made in Blender over " + os.path.basename(entry["file"])
                           + " (lumitrace add-on)")
    folder = os.path.dirname(entry["file"])
    for edit in changes:
        if edit.op == "set" and edit.usd_type == "asset" and edit.value and \
                not os.path.isabs(edit.value) and "://" not in edit.value:
            # as written in Blender, relative to the stage's folder: anchored anew here
            target = os.path.normpath(os.path.join(folder, edit.value))
            edit = dataclasses.replace(edit, value=layer_path(target, anchor or folder))
        author(layer, edit, Sdf, Gf, Vt)
    return layer


def layer_path(target: str, anchor: str | None) -> str:
    """``target`` as a layer names it from the folder ``anchor``: relative (``./``) where
    the two share a folder below the root, so the pair can move together; else absolute."""
    if anchor:
        try:
            shared = os.path.commonpath([target, anchor]) != os.path.abspath(os.sep)
        except ValueError:  # another drive
            shared = False
        if shared:
            rel = os.path.relpath(target, anchor).replace(os.sep, "/")
            return rel if rel.startswith(".") else "./" + rel
    return target.replace(os.sep, "/")


def _spec(layer, path: str, Sdf):
    spec = layer.GetPrimAtPath(path)
    if spec is None:
        spec = Sdf.CreatePrimInLayer(layer, path)
        spec.specifier = Sdf.SpecifierOver
    return spec


def _attribute(spec, name: str, type_name: str, Sdf, uniform: bool = False):
    attr = spec.attributes.get(name) if name in spec.attributes else None
    if attr is None:
        variability = Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying
        attr = Sdf.AttributeSpec(spec, name, Sdf.ValueTypeNames.Find(type_name), variability)
    return attr


def _apply(spec, api: str, Sdf) -> None:
    """Prepend ``api`` to the prim's apiSchemas (a list op: what the stage applies stays)."""
    if not api:
        return
    ops = spec.GetInfo("apiSchemas") if spec.HasInfo("apiSchemas") else Sdf.TokenListOp()
    items = list(ops.prependedItems)
    if api not in items:
        ops.prependedItems = items + [api]
    spec.SetInfo("apiSchemas", ops)


def usd_value(value, type_name: str, Sdf, Gf, Vt):
    """A plain value as the Sdf type ``type_name`` holds it."""
    if type_name == "point3f[]":
        flat = list(value)
        return Vt.Vec3fArray([Gf.Vec3f(*flat[i:i + 3]) for i in range(0, len(flat), 3)])
    if type_name == "int[]":
        return Vt.IntArray(list(value))
    if type_name == "float2[]":
        return Vt.Vec2fArray([Gf.Vec2f(float(a), float(b)) for a, b in value])
    if type_name == "float[]":
        return Vt.FloatArray([float(v) for v in value])
    if type_name == "color3f":
        return Gf.Vec3f(*map(float, value))
    if type_name == "double3":
        return Gf.Vec3d(*map(float, value))
    if type_name == "asset":
        return Sdf.AssetPath(value)
    return value


def author(layer, edit: state.Edit, Sdf, Gf, Vt) -> None:
    """Author one edit into ``layer``."""
    if edit.op == "define":
        spec = Sdf.CreatePrimInLayer(layer, edit.path)
        spec.specifier = Sdf.SpecifierDef
        spec.typeName = edit.type_name
        return
    spec = _spec(layer, edit.path, Sdf)
    if edit.op == "transform":
        m = edit.matrix
        attr = _attribute(spec, TRANSFORM_OP, "matrix4d", Sdf)
        attr.default = Gf.Matrix4d(*m)
        order = _attribute(spec, "xformOpOrder", "token[]", Sdf, uniform=True)
        order.default = Vt.TokenArray([TRANSFORM_OP])
    elif edit.op == "set":
        _apply(spec, edit.api, Sdf)
        attr = _attribute(spec, edit.prop, edit.usd_type, Sdf, edit.uniform)
        attr.default = usd_value(edit.value, edit.usd_type, Sdf, Gf, Vt)
    elif edit.op == "block":
        attr = _attribute(spec, edit.prop, edit.usd_type, Sdf, edit.uniform)
        attr.default = Sdf.ValueBlock()
    elif edit.op == "bind":
        _apply(spec, "MaterialBindingAPI", Sdf)
        rel = spec.relationships.get("material:binding") \
            if "material:binding" in spec.relationships else None
        if rel is None:
            rel = Sdf.RelationshipSpec(spec, "material:binding", False)
        rel.targetPathList.explicitItems = [Sdf.Path(edit.material)]
    elif edit.op == "connect":
        attr = _attribute(spec, edit.prop, edit.usd_type, Sdf)
        attr.connectionPathList.explicitItems = [Sdf.Path(edit.value)]
    elif edit.op == "active":
        spec.active = bool(edit.value)
    elif edit.op == "visibility":
        attr = _attribute(spec, "visibility", "token", Sdf)
        attr.default = "inherited" if edit.value else "invisible"
    else:
        raise ValueError(f"unknown edit {edit.op!r}")


def write_text(path: str, text: str) -> None:
    """Write ``text`` to ``path`` atomically (temporary file in its folder, flushed, then
    renamed over it)."""
    folder = os.path.dirname(path) or "."
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp",
                               dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
