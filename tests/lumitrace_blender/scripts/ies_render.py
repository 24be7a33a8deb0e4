"""Run in the bpy environment: the add-on's IES light rendered by Cycles on the CPU.

    python ies_render.py OUT_DIR

- calibration: a flat 1000 cd profile 2 m above a Lambertian floor of albedo 0.8, in a
  metre scene and in a millimetre scene: the floor's radiance at nadir (linear EXR);
- orientation: a profile lit only around C = 0 (then only around C = 90), gamma 20-60 deg,
  the light turned by 30 deg about z: where the lit patch's centroid lands on the floor.

Prints one JSON object as its last line."""
import json
import math
import os
import sys

import bpy
import mathutils

from lumitrace_blender import ies_light


def ies_text(lit) -> str:
    """A type C LM-63 profile, 10 deg steps: ``lit(c, gamma)`` candela."""
    hs, vs = list(range(0, 361, 10)), list(range(0, 181, 10))
    lines = ["IESNA:LM-63-2002", "TILT=NONE", f"1 1000 1 {len(vs)} {len(hs)} 1 2 0 0 0",
             "1 1 0", " ".join(map(str, vs)), " ".join(map(str, hs))]
    lines += [" ".join(f"{lit(h % 360, v):g}" for v in vs) for h in hs]
    return "\n".join(lines) + "\n"


def scene_with_floor(scale: float, size: float, samples: int, pixels: int):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = scale
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = pixels
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.view_settings.view_transform = "Standard"
    bpy.ops.mesh.primitive_plane_add(size=size * 4, location=(0, 0, 0))
    floor = bpy.context.object
    mat = bpy.data.materials.new("floor")
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    mat.node_tree.links.new(diffuse.outputs[0], nodes["Material Output"].inputs["Surface"])
    floor.data.materials.append(mat)
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(cam)
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = size
    cam.data.clip_end = 1e7
    cam.location = (0, 0, 3.0 / scale)  # 3 m up, above the light
    scene.camera = cam
    return scene


def render(scene, path):
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    w, h = img.size
    px = list(img.pixels)
    return w, h, [px[4 * i] for i in range(w * h)]


def calibration(out, scale):
    d = 2.0 / scale  # 2 m in the scene's units
    scene = scene_with_floor(scale, size=0.1 / scale, samples=16, pixels=8)
    ies_light.show_ies(scene, ies_text(lambda c, g: 1000.0),
                       mathutils.Matrix.Translation((0, 0, d)))
    w, h, red = render(scene, os.path.join(out, f"calibration_{scale:g}.exr"))
    return sum(red) / len(red)


def orientation(out, lit_c):
    scene = scene_with_floor(1.0, size=8.0, samples=16, pixels=48)
    turn = mathutils.Matrix.Rotation(math.radians(30), 4, "Z")
    ies_light.show_ies(scene, ies_text(lambda c, g: 1000.0 if c in lit_c and 20 <= g <= 60
                                       else 0.0),
                       mathutils.Matrix.Translation((0, 0, 1)) @ turn)
    w, h, red = render(scene, os.path.join(out, f"orientation_{min(lit_c)}.exr"))
    total = sum(red)
    x = sum(r * ((i % w) + 0.5 - w / 2) / w * 8 for i, r in enumerate(red)) / total
    y = sum(r * ((i // w) + 0.5 - h / 2) / h * 8 for i, r in enumerate(red)) / total
    return [x, y]


if __name__ == "__main__":
    out = sys.argv[sys.argv.index("--") + 1]
    report = {"radiance_m": calibration(out, 1.0), "radiance_mm": calibration(out, 0.001),
              "c0": orientation(out, {350, 0, 10}), "c90": orientation(out, {80, 90, 100})}
    print(json.dumps(report))
