"""Import a lumitrace stage into Blender in stage units, every ``lumitrace:`` value kept.

Each prim becomes what a designer expects (Xform: an empty, Mesh: a mesh, implicit gprims
tessellated, Rect/Disk/Sphere/Cylinder lights: Blender lights, Materials: materials with a
Principled BSDF of their UsdPreviewSurface), parented as the prims are, named after the
prims; a Blender location is the prim's translate (no unit or axis conversion of the
values). Every authored ``lumitrace:`` attribute becomes an ID property of the same name
on the object, material or light, with the schema's range as its limits. What the import
made is recorded (:mod:`.records`) so that an export writes only what changed.
"""
from __future__ import annotations

import math
import os
from array import array

import bpy
import mathutils

from . import records, schema, state
from .usd import pxr_modules

#: Display only: Cycles' candela-to-watt factor for IES data (D65: 177.83 lm/W), so a
#: light of flux F lm gets F / 177.83 W, scaled to the scene's units.
LUMENS_PER_WATT = 177.83
_LIGHT_TYPES = ("RectLight", "DiskLight", "SphereLight", "CylinderLight")
_IMPLICIT = ("Cube", "Sphere", "Cylinder", "Cone", "Capsule", "Plane")
_UNITS = {0.001: "MILLIMETERS", 0.01: "CENTIMETERS", 1.0: "METERS", 1000.0: "KILOMETERS"}


def import_stage(context, filepath: str, set_units: bool = True) -> dict:
    """Import the stage file ``filepath`` into ``context.scene``; returns its entry
    (file, luminaire, units, imported prims) and a list of ``warnings``."""
    Usd, Sdf, UsdGeom, UsdLux, UsdShade, Gf, Vt = pxr_modules()
    file = os.path.realpath(os.path.abspath(filepath))
    if not os.path.isfile(file):
        raise FileNotFoundError(f"no such stage file: {file}")
    stage = Usd.Stage.Open(file)
    if stage is None:
        raise ValueError(f"cannot open as a USD stage: {file}")
    default = stage.GetDefaultPrim()
    roots = [p for p in stage.GetPseudoRoot().GetChildren() if p.IsActive()]
    if not default and not roots:
        raise ValueError(f"the stage has no prim: {file}")
    luminaire = (default or roots[0]).GetPath().pathString
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    up = str(UsdGeom.GetStageUpAxis(stage))
    scene = context.scene
    earlier = _forget(file)
    importer = _Importer(scene, stage, file, luminaire, mpu)
    axes = None
    if up == "Y":  # Blender is Z-up: an unexported parent stands the Y-up stage upright
        axes = bpy.data.objects.new(os.path.basename(file) + " (Y up)", None)
        axes.rotation_euler = (math.pi / 2, 0.0, 0.0)
        axes[records.KEY] = {"stage": file, "prim": "", "kind": "axes"}
        importer.collection.objects.link(axes)
    importer.run(axes)
    if set_units:
        scene.unit_settings.system = "METRIC"
        scene.unit_settings.scale_length = mpu
        scene.unit_settings.length_unit = _UNITS.get(mpu, "ADAPTIVE")
    entry = {"file": file, "luminaire": luminaire, "metersPerUnit": mpu, "upAxis": up,
             "defaultPrim": default.GetName() if default else "",
             "objects": sorted(importer.objects), "materials": sorted(importer.materials),
             "material_scope": importer.material_scope}
    records.add_stage(scene, entry)
    if earlier:
        importer.warnings.append(f"{earlier} objects and materials of an earlier import of "
                                 "this stage are plain Blender data now (not exported)")
    return {**entry, "warnings": importer.warnings}


def _forget(file: str) -> int:
    """Unlink what an earlier import of ``file`` made from the stage (a second import
    would otherwise have two objects for one prim); returns how many."""
    count = 0
    for collection in (bpy.data.objects, bpy.data.materials, bpy.data.lights):
        for block in collection:
            rec = records.record(block)
            if rec is not None and rec.get("stage") == file:
                del block[records.KEY]
                count += 1
    return count


class _Importer:
    def __init__(self, scene, stage, file, luminaire, mpu):
        self.Usd, self.Sdf, self.UsdGeom, self.UsdLux, self.UsdShade, _, _ = pxr_modules()
        self.scene, self.stage, self.file, self.luminaire = scene, stage, file, luminaire
        self.mpu = mpu
        self.unit_scale = 1.0 / (mpu * mpu)
        name = os.path.basename(file)
        self.collection = bpy.data.collections.new(name)
        scene.collection.children.link(self.collection)
        self.objects: list[str] = []
        self.materials: dict[str, bpy.types.Material] = {}
        self.material_scope = ""
        self.face_maps: dict[str, list[int]] = {}
        self.warnings: list[str] = []

    def run(self, axes) -> None:
        Usd, UsdShade = self.Usd, self.UsdShade
        time = Usd.TimeCode.Default()
        it = iter(Usd.PrimRange(self.stage.GetPseudoRoot()))
        next(it)  # the pseudo-root
        parents: dict[str, object] = {"/": axes}
        made = []
        for prim in it:
            path = prim.GetPath().pathString
            parent_obj = parents.get(prim.GetPath().GetParentPath().pathString, axes)
            if prim.IsA(UsdShade.Material):
                self._material(prim)
                it.PruneChildren()
                continue
            if prim.IsInstance() or prim.GetTypeName() == "PointInstancer":
                self.warnings.append(f"{path}: instances are not imported")
                it.PruneChildren()
                continue
            obj = self._object(prim, time)
            if obj is None:
                parents[path] = parent_obj  # a Scope: its children sit on its parent
                continue
            obj.parent = parent_obj
            obj.matrix_parent_inverse = mathutils.Matrix.Identity(4)
            parents[path] = obj
            made.append((obj, prim))
        for obj, prim in made:  # the bindings once every material exists
            rec = records.record(obj)
            if rec["kind"] == "mesh":
                self._bind(obj, prim, rec)
            rec["state"] = state.object_state(obj, rec, {})
            obj[records.KEY] = rec
            self.objects.append(rec["prim"])

    # -- objects ---------------------------------------------------------------------------

    def _object(self, prim, time):
        UsdGeom, UsdLux = self.UsdGeom, self.UsdLux
        type_name = prim.GetTypeName()
        xformable = UsdGeom.Xformable(prim)
        if not xformable:
            return None
        name = prim.GetName()
        kind = "xform"
        if type_name == "Mesh":
            data, kind = self._mesh(prim, time), "mesh"
        elif type_name in _IMPLICIT:
            data, kind = self._implicit(prim, time), "mesh"
        elif type_name in _LIGHT_TYPES:
            data, kind = self._light(prim, time), "light"
        else:
            if prim.IsA(UsdLux.BoundableLightBase) or prim.IsA(UsdLux.NonboundableLightBase):
                self.warnings.append(f"{prim.GetPath()}: a {type_name} is not imported")
            data = None
        obj = bpy.data.objects.new(name, data)
        self.collection.objects.link(obj)
        m = xformable.GetLocalTransformation(time)
        usd_local = [float(m[r][c]) for r in range(4) for c in range(4)]
        obj.matrix_basis = mathutils.Matrix([[usd_local[4 * c + r] for c in range(4)]
                                             for r in range(4)])
        rec = {"stage": self.file, "prim": prim.GetPath().pathString, "kind": kind,
               "type": type_name, "usd_local": usd_local,
               "luminaire": prim.GetPath().pathString == self.luminaire}
        target = obj.data if kind == "light" else obj
        self._values(prim, target, time)
        if not self._visible(prim, time):
            obj.hide_render = True
            obj.hide_viewport = True
        obj[records.KEY] = rec
        return obj

    def _visible(self, prim, time) -> bool:
        attr = self.UsdGeom.Imageable(prim).GetVisibilityAttr()
        return not attr or attr.Get(time) != "invisible"

    def _mesh(self, prim, time):
        """A Blender mesh of the Mesh's points and faces (hole faces left out), built from
        the arrays' buffers."""
        UsdGeom = self.UsdGeom
        mesh = UsdGeom.Mesh(prim)
        points = _flat("f", mesh.GetPointsAttr().Get(time))
        counts = _flat("i", mesh.GetFaceVertexCountsAttr().Get(time))
        indices = _flat("i", mesh.GetFaceVertexIndicesAttr().Get(time))
        holes = set(mesh.GetHoleIndicesAttr().Get(time) or [])
        kept = [f for f in range(len(counts)) if f not in holes]
        if holes:  # the loops of the faces kept
            starts, at = [], 0
            for n in counts:
                starts.append(at)
                at += n
            indices = array("i", (v for f in kept
                                  for v in indices[starts[f]:starts[f] + counts[f]]))
            counts = array("i", (counts[f] for f in kept))
        self.face_maps[prim.GetPath().pathString] = kept
        starts, at = array("i", bytes(4 * len(counts))), 0
        for f, n in enumerate(counts):
            starts[f] = at
            at += n
        data = bpy.data.meshes.new(prim.GetName())
        data.vertices.add(len(points) // 3)
        data.vertices.foreach_set("co", points)
        data.loops.add(len(indices))
        data.loops.foreach_set("vertex_index", indices)
        data.polygons.add(len(counts))
        data.polygons.foreach_set("loop_start", starts)
        data.update()
        return data

    def _implicit(self, prim, time):
        """A tessellation of an implicit gprim, for display (its edits are not written)."""
        import bmesh
        kind = prim.GetTypeName()
        bm = bmesh.new()
        get = lambda name, d: (prim.GetAttribute(name).Get(time)  # noqa: E731
                               if prim.GetAttribute(name) else None) or d
        axis = get("axis", "Z")
        if kind == "Cube":
            bmesh.ops.create_cube(bm, size=float(get("size", 2.0)))
        elif kind in ("Sphere", "Capsule"):
            bmesh.ops.create_uvsphere(bm, u_segments=48, v_segments=24,
                                      radius=float(get("radius", 1.0)))
        elif kind in ("Cylinder", "Cone"):
            r = float(get("radius", 1.0))
            bmesh.ops.create_cone(bm, cap_ends=True, segments=48, radius1=r,
                                  radius2=r if kind == "Cylinder" else 0.0,
                                  depth=float(get("height", 2.0)))
        else:  # Plane
            bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=0.5)
            bmesh.ops.scale(bm, vec=(float(get("width", 2.0)), float(get("length", 2.0)), 1),
                            verts=bm.verts)
        turn = {"X": mathutils.Matrix.Rotation(math.pi / 2, 4, "Y"),
                "Y": mathutils.Matrix.Rotation(-math.pi / 2, 4, "X")}.get(axis)
        if turn is not None:
            bmesh.ops.transform(bm, matrix=turn, verts=bm.verts)
        data = bpy.data.meshes.new(prim.GetName())
        bm.to_mesh(data)
        bm.free()
        return data

    def _light(self, prim, time):
        type_name = prim.GetTypeName()
        get = lambda name, d: (prim.GetAttribute(name).Get(time)  # noqa: E731
                               if prim.GetAttribute(name) else None)
        def value(name, d):
            v = get(name, d)
            return d if v is None else float(v)
        if type_name in ("RectLight", "DiskLight", "CylinderLight"):
            light = bpy.data.lights.new(prim.GetName(), "AREA")
            if type_name == "RectLight":
                light.shape = "RECTANGLE"
                light.size = value("inputs:width", 1.0)
                light.size_y = value("inputs:height", 1.0)
            elif type_name == "DiskLight":
                light.shape = "DISK"
                light.size = 2.0 * value("inputs:radius", 0.5)
            else:  # display only: Blender has no cylinder light
                light.shape = "RECTANGLE"
                light.size = value("inputs:length", 1.0)
                light.size_y = 2.0 * value("inputs:radius", 0.5)
        else:
            light = bpy.data.lights.new(prim.GetName(), "POINT")
            light.shadow_soft_size = value("inputs:radius", 0.5)
        colour = get("inputs:color", None)
        if colour is not None:
            light.color = tuple(float(c) for c in colour)
        flux = get(schema.PREFIX + "luminousFlux", None)
        if flux:
            light.energy = float(flux) / LUMENS_PER_WATT * self.unit_scale
        return light

    def _values(self, prim, target, time) -> None:
        """The prim's authored ``lumitrace:`` values as ID properties of ``target``."""
        Sdf = self.Sdf
        for attr in prim.GetAttributes():
            name = attr.GetName()
            if not name.startswith(schema.PREFIX) or not attr.HasAuthoredValue():
                continue
            value = attr.Get(time)
            if value is None:
                continue
            set_property(target, name, _plain_value(value, attr.GetTypeName(), Sdf))

    def _bind(self, obj, prim, rec) -> None:
        UsdShade = self.UsdShade
        api = UsdShade.MaterialBindingAPI(prim)
        bound = _bound(api, UsdShade)
        rec["bindings"] = [rec["prim"]]
        slots = [self.materials.get(bound.GetPath().pathString) if bound else None]
        subsets = UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets() \
            if rec["type"] == "Mesh" else []
        face_of = {f: i for i, f in enumerate(self.face_maps.get(rec["prim"], []))}
        index = [0] * len(obj.data.polygons)
        for subset in subsets:
            mat = _bound(UsdShade.MaterialBindingAPI(subset.GetPrim()), UsdShade)
            rec["bindings"].append(subset.GetPath().pathString)
            slots.append(self.materials.get(mat.GetPath().pathString) if mat else None)
            for f in subset.GetIndicesAttr().Get() or []:
                if f in face_of:
                    index[face_of[f]] = len(slots) - 1
        rec["subsets"] = bool(subsets)
        if subsets or slots[0] is not None:
            for mat in slots:
                obj.data.materials.append(mat)
            if subsets:
                obj.data.polygons.foreach_set("material_index", index)

    # -- materials -------------------------------------------------------------------------

    def _material(self, prim) -> None:
        UsdShade = self.UsdShade
        path = prim.GetPath().pathString
        mat = bpy.data.materials.new(prim.GetName())
        mat.use_fake_user = True  # kept with the .blend even while nothing uses it
        mat.use_nodes = True
        self._values(prim, mat, self.Usd.TimeCode.Default())
        shader_path = ""
        source = UsdShade.Material(prim).ComputeSurfaceSource()
        shader = source[0] if source and source[0] else None
        node = state.principled(mat)
        if shader and shader.GetIdAttr().Get() == "UsdPreviewSurface" and node is not None:
            shader_path = shader.GetPath().pathString
            defaults = {"diffuseColor": (0.18, 0.18, 0.18), "roughness": 0.5,
                        "metallic": 0.0, "opacity": 1.0, "ior": 1.5}
            for usd_name, (socket, _) in state.PREVIEW_INPUTS.items():
                short = usd_name[len("inputs:"):]
                inp = shader.GetInput(short)
                value = inp.Get() if inp and not inp.HasConnectedSource() else None
                value = defaults[short] if value is None else value
                if short == "diffuseColor":
                    node.inputs[socket].default_value = (*map(float, value), 1.0)
                    mat.diffuse_color = (*map(float, value), 1.0)
                else:
                    node.inputs[socket].default_value = float(value)
        rec = {"stage": self.file, "prim": path, "shader": shader_path}
        rec["state"] = state.material_state(mat, rec)
        mat[records.KEY] = rec
        self.materials[path] = mat
        if not self.material_scope:
            self.material_scope = prim.GetPath().GetParentPath().pathString


def _flat(typecode: str, values) -> array:
    """A USD array (Vt, with the buffer protocol) as a flat ``array`` of ``typecode``."""
    out = array(typecode)
    if values is not None and len(values):
        out.frombytes(memoryview(values).cast("B"))
    return out


def _bound(api, UsdShade):
    for purpose in (UsdShade.Tokens.full, UsdShade.Tokens.allPurpose):
        found = api.ComputeBoundMaterial(purpose)
        material = found[0] if isinstance(found, tuple) else found
        if material:
            return material
    return None


def _plain_value(value, type_name, Sdf):
    """A USD value as an ID property can hold it."""
    if isinstance(value, Sdf.AssetPath):
        return value.path
    if hasattr(value, "__len__") and not isinstance(value, str):
        return [list(map(float, v)) if hasattr(v, "__len__") else
                (float(v) if isinstance(v, float) else v) for v in value]
    if isinstance(value, bool):
        return value
    return value if not isinstance(value, float) else float(value)


def set_property(target, name: str, value) -> None:
    """Set ``target[name]`` and, for a schema attribute, its limits and description."""
    target[name] = value
    attr = schema.BY_NAME.get(name)
    if attr is None or attr.usd_type not in ("float", "double", "int") or \
            isinstance(value, bool):
        return
    ui = target.id_properties_ui(name)
    limits = {}
    if attr.low is not None:
        limits["min"] = limits["soft_min"] = attr.low
    if attr.high is not None:
        limits["max"] = limits["soft_max"] = attr.high
    if attr.usd_type == "int":
        ui.update(description=attr.doc, **{k: int(v) for k, v in limits.items()})
    else:
        ui.update(description=attr.doc, precision=4, **limits)
