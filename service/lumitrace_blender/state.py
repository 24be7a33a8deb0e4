"""The state of an imported stage as Blender holds it, and the edits between two states.

A state maps ``(kind, prim path)`` to a dict of what Blender shows for that prim: its
placement, mesh digest, ``lumitrace:`` values, light size, preview-surface inputs,
material bindings, visibility. The import records the state it made; an export writes
the edits from that state to the current one, and the live link sends the edits from the
state it last sent. Both go through :func:`edits` so they always agree.
"""
from __future__ import annotations

import difflib
import hashlib
import re
from array import array
from dataclasses import dataclass, field

import bpy

from . import records, schema

#: Blender light shape -> the UsdLux size inputs it gives (stage units).
LIGHT_INPUTS = {"RectLight": ("inputs:width", "inputs:height"), "DiskLight": ("inputs:radius",),
                "SphereLight": ("inputs:radius",)}
#: UsdPreviewSurface input -> (Principled BSDF input, Sdf type).
PREVIEW_INPUTS = {"inputs:diffuseColor": ("Base Color", "color3f"),
                  "inputs:roughness": ("Roughness", "float"),
                  "inputs:metallic": ("Metallic", "float"),
                  "inputs:opacity": ("Alpha", "float"),
                  "inputs:ior": ("IOR", "float")}
_NAME = re.compile(r"[^A-Za-z0-9_]")


class ExportError(ValueError):
    """A change Blender holds that cannot be written as lumitrace reads it: ``where``
    names the Blender data and the prim, ``prop`` the property."""

    def __init__(self, message: str, where: str, prop: str = ""):
        self.where, self.prop = where, prop
        super().__init__(f"{where}{' ' + prop if prop else ''}: {message}")


@dataclass
class Edit:
    """One change to author over the stage: ``op`` is ``transform`` (``matrix``, USD's
    row-major row-vector convention, 16 values), ``set`` (``prop`` of Sdf type
    ``usd_type`` to ``value``, on a prim with ``api`` applied where the attribute is a
    lumitrace one), ``block`` (the attribute's authored value removed: a value block),
    ``bind`` (``material``), ``active`` (``value``), ``visibility`` (``value``) or
    ``define`` (a new prim of ``type_name``)."""

    op: str
    path: str
    prop: str = ""
    value: object = None
    usd_type: str = ""
    uniform: bool = False
    api: str = ""
    matrix: tuple = ()
    material: str = ""
    type_name: str = ""
    extra: dict = field(default_factory=dict)


# ------------------------------------------------------------------------------------------
# Reading Blender
# ------------------------------------------------------------------------------------------

def local_matrix(obj) -> list[float]:
    """The object's transform relative to its parent, row-major (Blender's convention:
    column vectors), 16 values."""
    m = obj.matrix_parent_inverse @ obj.matrix_basis
    return [float(m[i][j]) for i in range(4) for j in range(4)]


def usd_matrix(local: list[float], imported_local: list[float] | None,
               imported_usd: list[float] | None) -> tuple[float, ...]:
    """The USD local matrix (row-major, row vectors: translation in the last row) for the
    Blender ``local`` matrix. Where Blender's rotation and scale, or its translation, are
    the ones imported, the stage's own double values are kept bit for bit: a move keeps the
    part's orientation exactly as the stage had it."""
    out = [0.0] * 16
    same3 = imported_local is not None and all(
        local[4 * i + j] == imported_local[4 * i + j] for i in range(3) for j in range(3))
    same_t = imported_local is not None and all(
        local[4 * i + 3] == imported_local[4 * i + 3] for i in range(3))
    for r in range(3):
        for c in range(3):
            out[4 * r + c] = imported_usd[4 * r + c] if same3 else local[4 * c + r]
        out[12 + r] = imported_usd[12 + r] if same_t else local[4 * r + 3]
    out[15] = 1.0
    return tuple(float(v) for v in out)


def mesh_arrays(mesh) -> tuple[array, array, array]:
    """``(points, counts, indices)`` of a Blender mesh: float32 xyz, per-face vertex counts
    and the faces' vertex indices, as USD's Mesh holds them."""
    points = array("f", bytes(12 * len(mesh.vertices)))
    mesh.vertices.foreach_get("co", points)
    counts = array("i", bytes(4 * len(mesh.polygons)))
    mesh.polygons.foreach_get("loop_total", counts)
    indices = array("i", bytes(4 * len(mesh.loops)))
    mesh.loops.foreach_get("vertex_index", indices)
    return points, counts, indices


def mesh_digest(mesh) -> str:
    """SHA-256 of the mesh's points and faces."""
    h = hashlib.sha256()
    for a in mesh_arrays(mesh):
        h.update(len(a).to_bytes(8, "little"))
        h.update(a.tobytes())
    return h.hexdigest()


#: Mesh digests the live link keeps between its reads (by the mesh's address), dropped
#: when Blender's dependency graph says a mesh's geometry changed (see :func:`forget`).
_DIGESTS: dict[int, str] = {}


def cached_digest(mesh) -> str:
    """:func:`mesh_digest`, kept until the mesh is updated (a mesh of a million triangles
    takes most of a second to hash: too long to do ten times a second)."""
    key = mesh.as_pointer()
    digest = _DIGESTS.get(key)
    if digest is None:
        digest = _DIGESTS[key] = mesh_digest(mesh)
    return digest


def forget(scene=None, depsgraph=None) -> None:
    """``depsgraph_update_post`` handler: forget the digests of meshes whose geometry the
    update changed (all of them when it does not say which)."""
    if depsgraph is None:
        _DIGESTS.clear()
        return
    for update in depsgraph.updates:
        block = getattr(update.id, "original", update.id)
        if isinstance(block, bpy.types.Mesh):
            _DIGESTS.pop(block.as_pointer(), None)
        elif isinstance(block, bpy.types.Object) and block.type == "MESH" and \
                update.is_updated_geometry and block.data is not None:
            _DIGESTS.pop(block.data.as_pointer(), None)


def lumitrace_values(idblock) -> dict:
    """The ``lumitrace:`` ID properties of an object, material or light, as plain values."""
    return {k: records.plain(v) for k, v in idblock.items() if k.startswith(schema.PREFIX)}


def light_sizes(light, prim_type: str) -> dict:
    """The UsdLux size inputs a Blender light shows (stage units)."""
    if prim_type == "RectLight":
        square = light.shape in ("SQUARE", "DISK")
        return {"inputs:width": float(light.size),
                "inputs:height": float(light.size if square else light.size_y)}
    if prim_type == "DiskLight":
        return {"inputs:radius": float(light.size) / 2.0}
    if prim_type == "SphereLight":
        return {"inputs:radius": float(light.shadow_soft_size)}
    return {}


def preview_values(material) -> dict:
    """The UsdPreviewSurface inputs a material's Principled BSDF shows."""
    node = principled(material)
    if node is None:
        return {}
    out = {}
    for usd_name, (socket, _) in PREVIEW_INPUTS.items():
        value = node.inputs[socket].default_value
        out[usd_name] = [float(v) for v in value[:3]] if usd_name.endswith("Color") \
            else float(value)
    return out


def principled(material):
    """The material's Principled BSDF node (None where it has none)."""
    if material is None or not material.use_nodes or material.node_tree is None:
        return None
    for node in material.node_tree.nodes:
        if node.bl_idname == "ShaderNodeBsdfPrincipled":
            return node
    return None


def slot_materials(obj, new_paths: dict) -> list[str]:
    """The prim path of the material in each of the object's slots ("" for none; a
    material made in Blender by the path ``new_paths`` gives it)."""
    out = []
    for slot in obj.material_slots:
        mat = slot.material
        rec = records.record(mat) if mat is not None else None
        out.append(rec["prim"] if rec is not None else
                   new_paths.get(mat.name, "") if mat is not None else "")
    return out


def object_state(obj, rec: dict, new_paths: dict, cached: bool = False) -> dict:
    """What Blender shows now for an imported object (see :func:`state_of_stage`);
    ``cached``: mesh digests kept since the last update of the mesh."""
    out = {"exists": True, "local": local_matrix(obj), "visible": not obj.hide_render,
           "parent": parent_prim(obj)}
    if rec["kind"] == "light" and obj.data is not None:
        out["values"] = lumitrace_values(obj.data)
        out["light"] = light_sizes(obj.data, rec["type"])
    else:
        out["values"] = lumitrace_values(obj)
    if rec["kind"] == "mesh" and obj.type == "MESH":
        out["mesh"] = (cached_digest if cached else mesh_digest)(obj.data)
        out["slots"] = slot_materials(obj, new_paths)
    return out


def material_state(material, rec: dict) -> dict:
    return {"exists": True, "values": lumitrace_values(material),
            "preview": preview_values(material) if rec.get("shader") else {}}


def parent_prim(obj) -> str:
    """The prim path of the object's parent ("" at the stage's root)."""
    p = obj.parent
    while p is not None:
        rec = records.record(p)
        if rec is not None:
            return rec["prim"] if rec["kind"] != "axes" else ""
        return "?" + p.name  # a parent the stage does not have
    return ""


def imported_objects(stage_file: str):
    """``(object, record)`` of every object imported from ``stage_file``."""
    for obj in bpy.data.objects:
        rec = records.record(obj)
        if rec is not None and rec.get("stage") == stage_file and rec["kind"] != "axes":
            yield obj, rec


def imported_materials(stage_file: str):
    for mat in bpy.data.materials:
        rec = records.record(mat)
        if rec is not None and rec.get("stage") == stage_file:
            yield mat, rec


def state_of_stage(entry: dict, cached: bool = False) -> dict:
    """The current state of every prim imported from the stage ``entry``: ``(kind, prim)``
    -> state dict, kind ``object`` or ``material``; mesh objects made in Blender below an
    imported object as ``new``, and materials made in Blender that they or the imported
    objects use as ``new material``."""
    state = {}
    objects = list(imported_objects(entry["file"]))
    paths = {obj.name: rec["prim"] for obj, rec in objects}
    added = list(new_objects(entry, paths))
    new_paths = new_material_paths(entry, [o for o, _ in objects] + [o for o, _ in added])
    for obj, rec in objects:
        state[("object", rec["prim"])] = object_state(obj, rec, new_paths, cached)
    for mat, rec in imported_materials(entry["file"]):
        state[("material", rec["prim"])] = material_state(mat, rec)
    for obj, path in added:
        state[("new", path)] = new_object_state(obj, path, new_paths)
    for name, path in new_paths.items():
        mat = bpy.data.materials[name]
        state[("new material", path)] = {"exists": True, "name": name,
                                         "values": lumitrace_values(mat),
                                         "preview": preview_values(mat)}
    return state


def recorded_state(entry: dict) -> dict:
    """The state the import made (prims whose Blender data is gone count as existing)."""
    state = {}
    for obj, rec in imported_objects(entry["file"]):
        state[("object", rec["prim"])] = rec["state"]
    for mat, rec in imported_materials(entry["file"]):
        state[("material", rec["prim"])] = rec["state"]
    for path in entry.get("objects", []):
        state.setdefault(("object", path), {"exists": True})
    for path in entry.get("materials", []):
        state.setdefault(("material", path), {"exists": True})
    return state


def usd_name(name: str) -> str:
    """A valid USD prim name from a Blender name."""
    out = _NAME.sub("_", name) or "_"
    return out if not out[0].isdigit() else "_" + out


def _unique(base: str, taken: set) -> str:
    path, k = base, 1
    while path in taken:
        path, k = f"{base}_{k}", k + 1
    taken.add(path)
    return path


def new_objects(entry: dict, paths: dict):
    """Mesh objects made in Blender below an imported object of the stage: ``(object,
    prim path)`` each, the path under its parent's prim (the room around the luminaire,
    parented to nothing of it, is not the luminaire's)."""
    taken = set(paths.values()) | set(entry.get("objects", []))
    found = []
    for obj in sorted(bpy.data.objects, key=lambda o: o.name):
        if records.record(obj) is not None or obj.get(records.LIVE_KEY) or obj.type != "MESH":
            continue
        if obj.parent is not None and obj.parent.name in paths:
            found.append((obj, _unique(paths[obj.parent.name] + "/" + usd_name(obj.name),
                                       taken)))
    return found


def new_material_paths(entry: dict, objects) -> dict:
    """Blender material name -> the prim path a material made in Blender gets: beside the
    stage's materials (``Materials`` under the luminaire when it has none)."""
    folder = entry.get("material_scope") or entry["luminaire"] + "/Materials"
    taken = set(entry.get("materials", [])) | set(entry.get("objects", []))
    out = {}
    for obj in objects:
        for slot in obj.material_slots:
            mat = slot.material
            if mat is not None and records.record(mat) is None and mat.name not in out:
                out[mat.name] = _unique(folder + "/" + usd_name(mat.name), taken)
    return out


def new_object_state(obj, path: str, new_paths: dict) -> dict:
    points, counts, indices = mesh_arrays(obj.data)
    return {"exists": True, "type": "Mesh", "local": local_matrix(obj),
            "mesh": mesh_digest(obj.data), "points": points, "counts": counts,
            "indices": indices, "values": lumitrace_values(obj),
            "slots": slot_materials(obj, new_paths), "visible": not obj.hide_render,
            "name": obj.name}


# ------------------------------------------------------------------------------------------
# Edits between two states
# ------------------------------------------------------------------------------------------

def value_edits(path: str, before: dict, after: dict, where: str) -> list[Edit]:
    """``set`` (or ``block``) edits of the ``lumitrace:`` values that differ."""
    out = []
    for name in sorted(set(before) | set(after)):
        if schema.is_result(name):
            continue  # lumitrace's own output, never written from Blender
        old, new = before.get(name), after.get(name)
        if old == new:
            continue
        attr = schema.BY_NAME.get(name)
        if attr is None:
            near = difflib.get_close_matches(name, list(schema.BY_NAME), n=2, cutoff=0.6)
            hint = f": did you mean {' or '.join(near)}?" if near else ""
            raise ExportError("is not an attribute of the lumitrace schema" + hint, where,
                              name)
        if new is None:
            out.append(Edit("block", path, name, usd_type=attr.usd_type, api=attr.api,
                            uniform=attr.uniform))
            continue
        if attr.usd_type in ("float", "double") and isinstance(new, int) \
                and not isinstance(new, bool):
            new = float(new)
        if attr.usd_type == "int" and isinstance(new, float) and new == int(new):
            new = int(new)
        if attr.usd_type == "double3" and isinstance(new, list):
            new = tuple(float(v) for v in new)
        if attr.usd_type == "bool":
            new = bool(new)
        why = attr.check(new)
        if why:
            raise ExportError(why, where, name)
        out.append(Edit("set", path, name, new, attr.usd_type, attr.uniform, attr.api))
    return out


def object_edits(obj, path: str, rec: dict | None, before: dict, after: dict,
                 where: str) -> list[Edit]:
    """The edits of one imported object between two of its states."""
    if not after.get("exists"):
        return [Edit("active", path, value=False)] if before.get("exists") else []
    if rec is None:
        return []
    out = []
    if after["parent"] != rec["state"]["parent"]:
        raise ExportError("its parent changed in Blender; a USD prim is placed by its path, "
                          "so parent it back (or export a new object instead)", where)
    if before.get("local") != after["local"]:
        out.append(Edit("transform", path, matrix=usd_matrix(
            after["local"], rec["state"]["local"], rec["usd_local"])))
    if before.get("visible", True) != after["visible"]:
        out.append(Edit("visibility", path, value=after["visible"]))
    if "mesh" in after and before.get("mesh") != after["mesh"]:
        out += mesh_edits(obj, path, rec, where)
    out += value_edits(path, before.get("values", {}), after.get("values", {}), where)
    for name, value in after.get("light", {}).items():
        if before.get("light", {}).get(name) != value:
            if not value > 0:
                raise ExportError(f"must be > 0, got {value:g}", where, name)
            out.append(Edit("set", path, name, value, "float"))
    old_slots, targets = before.get("slots", []), rec.get("bindings") or [path]
    for i, material in enumerate(after.get("slots", [])):
        old = old_slots[i] if i < len(old_slots) else None
        if material != old and i < len(targets) and material:
            out.append(Edit("bind", targets[i], material=material))
    return out


def mesh_edits(obj, path: str, rec: dict, where: str) -> list[Edit]:
    """Points and faces of a mesh edited in Blender (its holes cleared: Blender has none)."""
    if rec.get("type") != "Mesh":
        raise ExportError(f"a {rec.get('type')} is an implicit surface: its tessellation "
                          "cannot be written back (edit a Mesh, or only move it)", where)
    if rec.get("subsets"):
        raise ExportError("its faces carry GeomSubsets (per-face materials) that new "
                          "topology would break", where)
    points, counts, indices = mesh_arrays(obj.data)
    return [Edit("set", path, "points", points, "point3f[]"),
            Edit("set", path, "faceVertexCounts", counts, "int[]"),
            Edit("set", path, "faceVertexIndices", indices, "int[]"),
            Edit("set", path, "holeIndices", array("i"), "int[]")]


def material_edits(path: str, rec: dict | None, before: dict, after: dict,
                   where: str) -> list[Edit]:
    if not after.get("exists") or rec is None:
        return []  # a material deleted in Blender stays in the stage: nothing binds it
    out = value_edits(path, before.get("values", {}), after.get("values", {}), where)
    for name, value in after.get("preview", {}).items():
        if before.get("preview", {}).get(name) != value:
            out.append(Edit("set", rec["shader"], name, value, PREVIEW_INPUTS[name][1]))
    return out


def new_object_edits(path: str, state: dict, where: str) -> list[Edit]:
    """A mesh made in Blender: defined with its faces, placement, values and material."""
    out = [Edit("define", path, type_name="Mesh"),
           Edit("set", path, "points", state["points"], "point3f[]"),
           Edit("set", path, "faceVertexCounts", state["counts"], "int[]"),
           Edit("set", path, "faceVertexIndices", state["indices"], "int[]"),
           Edit("set", path, "orientation", "rightHanded", "token", uniform=True),
           Edit("set", path, "subdivisionScheme", "none", "token", uniform=True),
           Edit("transform", path, matrix=usd_matrix(state["local"], None, None))]
    out += value_edits(path, {}, state["values"], where)
    materials = [m for m in state["slots"] if m]
    if materials:
        out.append(Edit("bind", path, material=materials[0]))
    if not state["visible"]:
        out.append(Edit("visibility", path, value=False))
    return out


def new_material_edits(path: str, state: dict, where: str) -> list[Edit]:
    """A material made in Blender: a Material with its lumitrace values and a
    UsdPreviewSurface of its Principled BSDF."""
    shader = path + "/PreviewSurface"
    out = [Edit("define", path, type_name="Material"),
           Edit("define", shader, type_name="Shader"),
           Edit("set", shader, "info:id", "UsdPreviewSurface", "token", uniform=True)]
    for name, value in state["preview"].items():
        out.append(Edit("set", shader, name, value, PREVIEW_INPUTS[name][1]))
    out.append(Edit("connect", path, "outputs:surface", shader + ".outputs:surface", "token"))
    out += value_edits(path, {}, state["values"], where)
    return out


def edits(entry: dict, before: dict, after: dict) -> list[Edit]:
    """Every edit from state ``before`` to state ``after`` of the stage ``entry``, new
    prims first (a material before the mesh bound to it), then the edits of the stage's
    own prims in path order."""
    recs = {}
    for obj, rec in imported_objects(entry["file"]):
        recs[("object", rec["prim"])] = (obj, rec, f"object {obj.name!r} ({rec['prim']})")
    for mat, rec in imported_materials(entry["file"]):
        recs[("material", rec["prim"])] = (mat, rec,
                                           f"material {mat.name!r} ({rec['prim']})")
    created: list[Edit] = []
    changed: list[Edit] = []
    order = {"new material": 0, "new": 1, "material": 2, "object": 2}
    for key in sorted(set(before) | set(after), key=lambda k: (order[k[0]], k[1])):
        kind, path = key
        old, new = before.get(key, {}), after.get(key, {"exists": False})
        block, rec, where = recs.get(key, (None, None, f"{kind} {path}"))
        if kind == "object":
            changed += object_edits(block, path, rec, old, new, where)
        elif kind == "material":
            changed += material_edits(path, rec, old, new, where)
        elif not new.get("exists") or _same(old, new):
            continue
        elif kind == "new":
            created += new_object_edits(path, new, f"new object {new['name']!r} ({path})")
        else:
            created += new_material_edits(path, new, f"new material {new['name']!r} ({path})")
    return created + changed


def _same(a: dict, b: dict) -> bool:
    keys = set(a) | set(b)
    return all(_plain_eq(a.get(k), b.get(k)) for k in keys)


def _plain_eq(a, b) -> bool:
    if isinstance(a, array) or isinstance(b, array):
        return a is not None and b is not None and list(a) == list(b)
    return a == b
