"""The lumitrace panels: the schema's values of a material, an object and a light (each
editable within the schema's range, missing ones added with one click), and the live
link's state in the 3D view's sidebar and the scene properties."""
from __future__ import annotations

import bpy

from . import live, records, schema


def draw_values(layout, idblock, api: str, target: str) -> None:
    """One row per attribute of ``api``: its value where ``idblock`` has it, else a button
    adding it with the schema's fallback."""
    for attr in schema.BY_API[api]:
        if attr.name in idblock:
            layout.prop(idblock, f'["{attr.name}"]', text=attr.label)
        else:
            row = layout.row()
            row.label(text=f"{attr.label}: (schema default)")
            op = row.operator("lumitrace.add_attribute", text="", icon="ADD")
            op.name, op.target = attr.name, target
    results = sorted(k for k in idblock.keys() if schema.is_result(k))
    if results:
        box = layout.box()
        box.label(text="Traced result (written by lumitrace)")
        for name in results:
            value = idblock[name]
            shown = f"{value:.6g}" if isinstance(value, float) else str(value)
            box.label(text=f"{name[len(schema.RESULT_PREFIX):]}: {shown}")


def _prim_label(layout, idblock) -> None:
    rec = records.record(idblock)
    if rec is not None:
        layout.label(text=rec["prim"], icon="OUTLINER_DATA_EMPTY")


class LUMITRACE_PT_material(bpy.types.Panel):
    bl_label = "lumitrace"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return context.material is not None

    def draw(self, context):
        _prim_label(self.layout, context.material)
        draw_values(self.layout, context.material, schema.MATERIAL_API, "MATERIAL")


class LUMITRACE_PT_object(bpy.types.Panel):
    bl_label = "lumitrace"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type in ("MESH", "EMPTY")

    def draw(self, context):
        obj = context.object
        _prim_label(self.layout, obj)
        rec = records.record(obj)
        if rec is not None and rec.get("luminaire"):
            draw_values(self.layout, obj, schema.LUMINAIRE_API, "OBJECT")
        elif obj.type == "MESH":
            self.layout.label(text="Material values on the part itself:")
            draw_values(self.layout, obj, schema.MATERIAL_API, "OBJECT")
            if any(a.name in obj for a in schema.BY_API[schema.PROFILE_API]):
                self.layout.label(text="Generating profile (lumitrace remakes the mesh):")
                draw_values(self.layout, obj, schema.PROFILE_API, "OBJECT")


class LUMITRACE_PT_light(bpy.types.Panel):
    bl_label = "lumitrace"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "LIGHT" \
            and not context.object.get(records.LIVE_KEY)

    def draw(self, context):
        _prim_label(self.layout, context.object)
        draw_values(self.layout, context.object.data, schema.EMITTER_API, "LIGHT")


def draw_link(layout, context) -> None:
    """The live link's state: the service, revision, photons, error and key figures."""
    link = live.LINKS.get(context.scene.name)
    if link is None:
        op = layout.operator("lumitrace.connect", icon="LINKED")
        op.url = context.scene.get("_lumitrace_url", "http://127.0.0.1:8650")
        return
    s, r = link.status, link.results
    photometry = r.get("photometry", {})
    col = layout.column(align=True)
    col.label(text=link.service.url, icon="LINKED")
    col.label(text=f"revision {s.get('revision', link.revision)} ({s.get('state', '?')}), "
                   f"light from {link.light_revision}")
    if s.get("photons") is not None:
        error = 100 * (s.get("relative_error") or 0)
        col.label(text=f"{s['photons']:,} photons, error {error:.2f}%")
    if photometry:
        col.label(text=f"flux {photometry['luminous_flux']:.1f} "
                       f"± {photometry['luminous_flux_error']:.1f} lm")
        col.label(text=f"LOR {r['light_output_ratio']:.4f} "
                       f"± {r.get('light_output_ratio_error', 0):.4f}")
        col.label(text=f"peak {photometry['peak_intensity']:.1f} "
                       f"± {photometry['peak_intensity_error']:.1f} cd")
        beam = photometry.get("beam_angle_c0_c180")
        if beam is not None:
            col.label(text=f"beam C0-C180 {beam:.1f}°")
    if link.error:
        layout.label(text=link.error.splitlines()[0], icon="ERROR")
    layout.operator("lumitrace.disconnect", icon="UNLINKED")


class LUMITRACE_PT_link(bpy.types.Panel):
    bl_label = "lumitrace"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "lumitrace"

    def draw(self, context):
        layout = self.layout
        row = layout.row(align=True)
        row.operator("lumitrace.import_stage", text="Import", icon="IMPORT")
        row.operator("lumitrace.export_stage", text="Export", icon="EXPORT")
        draw_link(layout, context)


class LUMITRACE_PT_scene_link(bpy.types.Panel):
    bl_label = "lumitrace live link"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "scene"

    def draw(self, context):
        draw_link(self.layout, context)


CLASSES = (LUMITRACE_PT_material, LUMITRACE_PT_object, LUMITRACE_PT_light,
           LUMITRACE_PT_link, LUMITRACE_PT_scene_link)
