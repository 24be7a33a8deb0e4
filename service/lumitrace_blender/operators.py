"""The add-on's operators: ``bpy.ops.lumitrace.import_stage``, ``export_stage``,
``connect``, ``disconnect``, ``add_attribute``."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper

from . import exporter, importer, live, records, schema, state
from .http import ServiceError


class LUMITRACE_OT_import_stage(bpy.types.Operator, ImportHelper):
    """Import a lumitrace luminaire stage in stage units, keeping every lumitrace value"""

    bl_idname = "lumitrace.import_stage"
    bl_label = "Import lumitrace stage"
    bl_options = {"REGISTER", "UNDO"}
    filename_ext = ".usda"
    filter_glob: StringProperty(default="*.usd;*.usda;*.usdc;*.usdz", options={"HIDDEN"})
    set_units: BoolProperty(name="Set scene units", default=True,
                            description="Set the scene's unit scale to the stage's "
                                        "metersPerUnit, so lengths show in real units")

    def execute(self, context):
        try:
            entry = importer.import_stage(context, self.filepath, set_units=self.set_units)
        except (OSError, ValueError, ImportError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        for warning in entry["warnings"]:
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"imported {len(entry['objects'])} prims and "
                              f"{len(entry['materials'])} materials of {entry['file']}")
        return {"FINISHED"}


class LUMITRACE_OT_export_stage(bpy.types.Operator, ExportHelper):
    """Write what changed in Blender as opinions over the original stage"""

    bl_idname = "lumitrace.export_stage"
    bl_label = "Export lumitrace stage"
    filename_ext = ".usda"
    filter_glob: StringProperty(default="*.usda", options={"HIDDEN"})
    mode: EnumProperty(
        name="Form", default="stage",
        items=[("stage", "Stage over the original",
                "A stage that sublayers the original and holds the edits"),
               ("edits", "Edits layer", "The edits alone (lumitrace trace STAGE --edits)")])
    stage: StringProperty(name="Stage", default="",
                          description="The imported stage file (default: the last imported)")

    def execute(self, context):
        try:
            entry = records.stage_entry(context.scene, self.stage or None)
            done = exporter.export_stage(entry, self.filepath, self.mode)
        except (LookupError, state.ExportError, OSError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"wrote {done['edits']} edits to {done['file']}")
        return {"FINISHED"}


class LUMITRACE_OT_connect(bpy.types.Operator):
    """Link the imported stage to a running lumitrace serve: edits go to it as scene
    deltas, its newest result comes back as an IES light"""

    bl_idname = "lumitrace.connect"
    bl_label = "Connect to lumitrace serve"
    url: StringProperty(name="URL", default="http://127.0.0.1:8650")
    token: StringProperty(name="Token", default="", subtype="PASSWORD",
                          options={"SKIP_SAVE"})
    stage: StringProperty(name="Stage", default="")
    debounce: FloatProperty(name="Debounce (s)", default=live.DEBOUNCE, min=0.0, max=10.0)

    def execute(self, context):
        try:
            link = live.connect(context.scene, self.url, self.token or None,
                                self.stage or None, debounce=self.debounce)
        except (LookupError, ServiceError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        context.scene["_lumitrace_url"] = self.url
        self.report({"INFO"}, f"linked to {link.service.url} at revision {link.revision}")
        return {"FINISHED"}


class LUMITRACE_OT_disconnect(bpy.types.Operator):
    """Stop the live link"""

    bl_idname = "lumitrace.disconnect"
    bl_label = "Disconnect"

    def execute(self, context):
        live.disconnect(context.scene)
        return {"FINISHED"}


class LUMITRACE_OT_add_attribute(bpy.types.Operator):
    """Give the object, material or light a lumitrace attribute (its schema fallback)"""

    bl_idname = "lumitrace.add_attribute"
    bl_label = "Add lumitrace attribute"
    bl_options = {"REGISTER", "UNDO"}
    name: StringProperty(name="Attribute")
    target: EnumProperty(items=[("OBJECT", "Object", ""), ("MATERIAL", "Material", ""),
                                ("LIGHT", "Light", "")], name="On")

    def execute(self, context):
        attr = schema.BY_NAME.get(self.name)
        if attr is None:
            self.report({"ERROR"}, f"not a lumitrace attribute: {self.name}")
            return {"CANCELLED"}
        idblock = target_of(context, self.target)
        if idblock is None:
            self.report({"ERROR"}, "nothing to add it to")
            return {"CANCELLED"}
        value = attr.fallback
        if value is None:
            value = {"float2[]": [[555.0, 1.0]], "float[]": [0.0] * 6, "string": "",
                     "asset": "", "double": 0.0}.get(attr.usd_type, 0.0)
        importer.set_property(idblock, attr.name, value)
        return {"FINISHED"}


def target_of(context, target: str):
    obj = context.object
    if target == "MATERIAL":
        return context.material
    if target == "LIGHT":
        return obj.data if obj is not None and obj.type == "LIGHT" else None
    return obj


CLASSES = (LUMITRACE_OT_import_stage, LUMITRACE_OT_export_stage, LUMITRACE_OT_connect,
           LUMITRACE_OT_disconnect, LUMITRACE_OT_add_attribute)
