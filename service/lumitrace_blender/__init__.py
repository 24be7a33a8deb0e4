"""lumitrace for Blender: import a luminaire stage with every lumitrace value, export the
changes as opinions over the original stage, and link Blender live to ``lumitrace serve``.

Pure ``bpy`` and the standard library (and the OpenUSD module Blender ships): it imports
nothing of the ``lumitrace`` package, whose dependencies Blender's Python does not have.
Enable it with ``service/`` on Blender's Python path (see docs/blender.md)."""

bl_info = {
    "name": "lumitrace",
    "author": "lumitrace",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "File > Import/Export, View3D > Sidebar > lumitrace",
    "description": "Luminaire stages with their photometric properties, and a live link "
                   "to the lumitrace photon tracer",
    "category": "Import-Export",
}


def _menu_import(self, context):
    self.layout.operator("lumitrace.import_stage", text="lumitrace stage (.usd*)")


def _menu_export(self, context):
    self.layout.operator("lumitrace.export_stage", text="lumitrace stage edits (.usda)")


def register():
    import bpy

    from . import operators, panels, state
    for cls in operators.CLASSES + panels.CLASSES:
        bpy.utils.register_class(cls)
    if state.forget not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(state.forget)
    bpy.types.TOPBAR_MT_file_import.append(_menu_import)
    bpy.types.TOPBAR_MT_file_export.append(_menu_export)


def unregister():
    import bpy

    from . import live, operators, panels, state
    for scene in bpy.data.scenes:
        live.disconnect(scene)
    if state.forget in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(state.forget)
    bpy.types.TOPBAR_MT_file_import.remove(_menu_import)
    bpy.types.TOPBAR_MT_file_export.remove(_menu_export)
    for cls in reversed(operators.CLASSES + panels.CLASSES):
        bpy.utils.unregister_class(cls)
