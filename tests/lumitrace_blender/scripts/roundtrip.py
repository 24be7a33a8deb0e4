"""Run in the bpy environment (``tests/lumitrace_blender``): the add-on's import and export.

    python roundtrip.py demo STAGE OUT_DIR    the demo edited as the round-trip test asks
    python roundtrip.py many STAGE OUT_DIR    every kind of change, exported and as deltas
    python roundtrip.py stages OUT_DIR STAGE...    every stage imported and exported as is

Prints one JSON object as its last line."""
import json
import os
import sys

import bpy

import bmesh
import fake_layout

import lumitrace_blender
from lumitrace_blender import exporter, live, panels, records, state

REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
SPEC = "lumitrace:specularReflectance"


def fresh():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.ops.lumitrace, "import_stage") or \
            not hasattr(bpy.types, "LUMITRACE_OT_import_stage"):
        lumitrace_blender.register()


def by_prim(collection, path):
    for block in collection:
        rec = records.record(block)
        if rec is not None and rec["prim"] == path:
            return block
    raise LookupError(path)


def demo(stage, out):
    fresh()
    assert bpy.ops.lumitrace.import_stage(filepath=stage) == {"FINISHED"}
    reflector = by_prim(bpy.data.materials, REFLECTOR)
    diffuser = by_prim(bpy.data.objects, "/Luminaire/Diffuser")
    report = {"imported_value": reflector[SPEC],
              "ui": reflector.id_properties_ui(SPEC).as_dict(),
              "diffuser_location": list(diffuser.location)}
    diffuser.location.z -= 5.0  # 5 stage units down
    reflector[SPEC] = 0.5
    exported = os.path.join(out, "downlight.blender.usda")
    edits = os.path.join(out, "downlight.blender-edits.usda")
    assert bpy.ops.lumitrace.export_stage(filepath=exported) == {"FINISHED"}
    assert bpy.ops.lumitrace.export_stage(filepath=edits, mode="edits") == {"FINISHED"}
    entry = records.stage_entry(bpy.context.scene)
    report["edits"] = [[e.op, e.path, e.prop] for e in exporter.edits_since_import(entry)]
    # bad values are refused with the prim and property named, and nothing is written
    refusals = {}
    diffuser_material = by_prim(bpy.data.materials, "/Luminaire/Materials/DiffuserOpal")
    for name, value in (("lumitrace:transmittance", 1.5),
                        ("lumitrace:diffuseReflectance", 0.5),
                        ("lumitrace:scattering", "shiny")):
        before = diffuser_material.get(name)
        diffuser_material[name] = value
        try:
            exporter.export_stage(entry, exported)
            refusals[name] = None
        except state.ExportError as exc:
            refusals[name] = str(exc)
        if before is None:
            del diffuser_material[name]
        else:
            diffuser_material[name] = before
    report["refusals"] = refusals
    # an asset path typed in Blender is relative to the stage's folder: an export
    # elsewhere anchors it anew
    led = by_prim(bpy.data.objects, "/Luminaire/LED").data
    led["lumitrace:rayFile"] = "rays/led.tm25"
    os.makedirs(os.path.join(out, "elsewhere"), exist_ok=True)
    away = os.path.join(out, "elsewhere", "edits.usda")
    exporter.export_stage(entry, away, "edits")
    report["asset_line"] = [line.strip() for line in open(away) if "rayFile" in line]
    report["asset_delta"] = [d for d in live.deltas_of(entry, exporter.edits_since_import(
        entry)) if d.get("property") == "lumitrace:rayFile"]
    del led["lumitrace:rayFile"]
    # a second import of the stage: the first one's data is no longer the stage's
    assert bpy.ops.lumitrace.import_stage(filepath=stage) == {"FINISHED"}
    report["after_reimport"] = len(exporter.edits_since_import(
        records.stage_entry(bpy.context.scene)))
    report["exported"], report["edits_layer"] = exported, edits
    return report


def many(stage, out):
    """Every kind of change Blender can make, exported and as the live link's deltas."""
    fresh()
    assert bpy.ops.lumitrace.import_stage(filepath=stage) == {"FINISHED"}
    scene = bpy.context.scene
    reflector = by_prim(bpy.data.materials, REFLECTOR)
    report = {"panels": {
        "material": fake_layout.draw(panels.LUMITRACE_PT_material, material=reflector),
        "light": fake_layout.draw(panels.LUMITRACE_PT_light,
                                  object=by_prim(bpy.data.objects, "/Luminaire/LED")),
        "luminaire": fake_layout.draw(panels.LUMITRACE_PT_object,
                                      object=by_prim(bpy.data.objects, "/Luminaire"))}}
    led = by_prim(bpy.data.objects, "/Luminaire/LED")
    led.data["lumitrace:luminousFlux"] = 1500.0  # a flux
    led.data.size = 25.0  # the rect light's width
    board = by_prim(bpy.data.objects, "/Luminaire/Board")
    kept = state.cached_digest(board.data)
    for v in board.data.vertices:  # a mesh edit: the board 10% smaller across
        v.co.x *= 0.9
        v.co.y *= 0.9
    report["digest_kept_until_update"] = state.cached_digest(board.data) == kept
    board.data.update()
    bpy.context.view_layer.update()  # the depsgraph tells the add-on the mesh changed
    report["digest_after_update"] = state.cached_digest(board.data) == \
        state.mesh_digest(board.data) != kept
    housing_paint = by_prim(bpy.data.materials, "/Luminaire/Materials/HousingPaint")
    state.principled(housing_paint).inputs["Base Color"].default_value = (0.2, 0.2, 0.2, 1)
    housing = by_prim(bpy.data.objects, "/Luminaire/Housing")  # another material bound
    housing.material_slots[0].material = by_prim(bpy.data.materials,
                                                 "/Luminaire/Materials/BoardWhite")
    diffuser = by_prim(bpy.data.objects, "/Luminaire/Diffuser")
    diffuser.rotation_euler.z = 0.2618  # turned 15 deg and moved
    diffuser.location = (1.0, 0.0, -3.0)
    # a new part under the luminaire with a new material
    mesh = bpy.data.meshes.new("Baffle")
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=10.0)
    bm.to_mesh(mesh)
    bm.free()
    baffle = bpy.data.objects.new("Baffle", mesh)
    scene.collection.objects.link(baffle)
    baffle.parent = by_prim(bpy.data.objects, "/Luminaire")
    baffle.location = (0.0, 0.0, -20.0)
    black = bpy.data.materials.new("BaffleBlack")
    black.use_nodes = True
    black["lumitrace:scattering"] = "diffuse"
    black["lumitrace:reflectance"] = 0.05
    mesh.materials.append(black)
    del reflector["lumitrace:roughness"]  # a value removed: blocked (the fallback)
    board.hide_render = True  # hidden from renders: invisible
    bpy.data.objects.remove(by_prim(bpy.data.objects, "/Luminaire/Reflector"))  # inactive
    # a room object beside the luminaire: not the luminaire's, never exported
    bpy.ops.mesh.primitive_plane_add(size=3000, location=(0, 0, -2400))
    entry = records.stage_entry(scene)
    changes = exporter.edits_since_import(entry)
    report["edits"] = sorted({(e.op, e.path, e.prop) for e in changes})
    exported = os.path.join(out, "many.blender.usda")
    exporter.export_stage(entry, exported)
    report["exported"] = exported
    report["deltas"] = live.deltas_of(entry, changes)
    return report


def stages(out, paths):
    report = {}
    for path in paths:
        fresh()
        assert bpy.ops.lumitrace.import_stage(filepath=path) == {"FINISHED"}
        entry = records.stage_entry(bpy.context.scene)
        name = os.path.splitext(os.path.basename(path))[0]
        exported = os.path.join(out, name + ".blender.usda")
        done = exporter.export_stage(entry, exported)
        report[path] = {"exported": exported, "edits": done["edits"],
                        "objects": len(entry["objects"]),
                        "materials": len(entry["materials"])}
    return report


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    if args[0] == "demo":
        result = demo(args[1], args[2])
    elif args[0] == "many":
        result = many(args[1], args[2])
    else:
        result = stages(args[1], args[2:])
    print(json.dumps(result))
