"""Run in the bpy environment (``tests/blender``): the add-on's import and export.

    python roundtrip.py demo STAGE OUT_DIR    the demo edited as the round-trip test asks
    python roundtrip.py stages OUT_DIR STAGE...    every stage imported and exported as is

Prints one JSON object as its last line."""
import json
import os
import sys

import bpy

import lumitrace_blender
from lumitrace_blender import exporter, records, state

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
    report["exported"], report["edits_layer"] = exported, edits
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
    else:
        result = stages(args[1], args[2:])
    print(json.dumps(result))
