"""A scripted session of the Blender add-on's live link to a running ``lumitrace serve``
of the demo downlight (run it in the Blender environment, ``.venv-blender``)::

    .venv-blender/bin/python tools/blender_live_session.py URL STAGE --out DIR
        [--photons N] [--render WxH] [--samples S] [--denoise]

The stage (the file the service serves) is imported and linked, the link's clock driven
here, so that the debounce is shown by the clock and not by sleeping. The diffuser is
dragged 5 stage units down in ten steps 0.05 s apart, then left: one delta. Once the
service has written that revision's last result the photometric light holds its IES;
with ``--render`` a white room around the luminaire (3 m x 3 m x 2.4 m, the luminaire in
the middle of its ceiling) is rendered by Cycles on the CPU. Then the reflector's specular
reflectance is set to 0.5, and the room rendered again once the service's new result is
in the light. ``N`` is the service's photon budget (its ``--photons``): a revision's last
result is the one of N photons with its pictures.

Prints one JSON object as its last line: the batches sent, the revisions, the light's IES
(SHA-256 of its text, also written to DIR/light.ies) and the pictures' mean values.
"""
import argparse
import hashlib
import json
import math
import os
import sys

import bpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "service"))
import lumitrace_blender  # noqa: E402  (the add-on beside lumitrace, in service/)
from lumitrace_blender import ies_light, live, panels, records  # noqa: E402

REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
SPEC = "lumitrace:specularReflectance"


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def by_prim(collection, path):
    for block in collection:
        rec = records.record(block)
        if rec is not None and rec["prim"] == path:
            return block
    raise LookupError(path)


def room(scene, size=(96, 72), samples=16, denoise=False):
    """A white room 3 m x 3 m x 2.4 m (the stage's millimetres, open on one side), the
    luminaire recessed in the middle of its ceiling; a camera at the open side."""
    mat = bpy.data.materials.new("room white")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = \
        (0.7, 0.7, 0.7, 1)
    mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 1.0
    for name, location, rotation, extent in (
            ("floor", (0, 0, -2400), (0, 0, 0), 3000),
            ("wall +x", (1500, 0, -1200), (0, 1.5708, 0), 3000),
            ("wall -x", (-1500, 0, -1200), (0, 1.5708, 0), 3000),
            ("wall +y", (0, 1500, -1200), (1.5708, 0, 0), 3000),
            ("ceiling", (0, 0, 0.5), (0, 0, 0), 3000)):
        bpy.ops.mesh.primitive_plane_add(size=extent, location=location, rotation=rotation)
        bpy.context.object.name = name
        bpy.context.object.data.materials.append(mat)
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(cam)
    cam.data.lens = 12
    cam.data.clip_start, cam.data.clip_end = 10, 20000
    cam.location = (0, -1450, -1500)  # at the open side, 0.9 m above the floor
    cam.rotation_euler = (math.radians(98), 0, 0)  # the ceiling's luminaire in view
    scene.camera = cam
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = denoise
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.image_settings.file_format = "PNG"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.exposure = 2.0
    world = bpy.data.worlds.new("black")
    world.color = (0, 0, 0)
    scene.world = world


def render(scene, path) -> float:
    """Render to ``path`` (PNG); the mean of its pixels' red, green and blue (0-1)."""
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    px = img.pixels[:]
    return sum(px[i] + px[i + 1] + px[i + 2] for i in range(0, len(px), 4)) / (len(px) * 0.75)


def wait_written(link, revision, photons):
    """Take the service's events until the last result of ``revision`` (None: of the
    newest revision, whichever it is when it is reached) is written (all ``photons``, with
    its pictures: nothing is written for it after that), then load the service's newest
    result into the light; returns that revision."""
    while True:
        status = link.service.status()
        target = status["revision"] if revision is None else revision
        if status["written_revision"] == target and status["written_photons"] == photons \
                and status["written_pictures"] and status["revision"] == target:
            break
        link.wait_for(lambda kind, data: kind in ("written", "revision"), timeout=240)
    link.refresh()
    assert link.light_revision == target, (link.light_revision, target)
    return target


def panel_text(scene) -> list[str]:
    """The texts the live link's panel shows (a panel draws only in a window, which
    Blender as a module has not: a stand-in layout records them)."""
    texts = []

    class Layout:
        def column(self, **kwargs):
            return self

        def label(self, text="", **kwargs):
            texts.append(text)

        def operator(self, *args, **kwargs):
            return argparse.Namespace()

    panels.draw_link(Layout(), argparse.Namespace(scene=scene))
    return texts


def main(url, stage, out, photons, size=None, samples=16, denoise=False):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    lumitrace_blender.register()
    scene = bpy.context.scene
    assert bpy.ops.lumitrace.import_stage(filepath=stage) == {"FINISHED"}
    do_render = size is not None
    if do_render:
        room(scene, size, samples, denoise)
    assert bpy.ops.lumitrace.connect(url=url) == {"FINISHED"}
    link = live.LINKS[scene.name]
    clock = link.clock = Clock()  # the session's own clock from here on
    link.changed_at = clock()
    report = {"connected_revision": wait_written(link, None, photons)}

    # the drag: ten moves 0.05 s apart send nothing; once it holds still, one delta
    diffuser = by_prim(bpy.data.objects, "/Luminaire/Diffuser")
    answers = []
    for step in range(1, 11):
        diffuser.location.z = -0.5 * step
        clock.now += 0.05
        answers.append(link.poll())
    clock.now += 0.05
    answers.append(link.poll())  # still within the debounce
    clock.now += live.DEBOUNCE + 0.01
    answers.append(link.poll())
    report["drag_answers"] = [a is not None for a in answers]
    report["batches"] = [list(b) for b in link.batches]
    moved = link.sent_revisions[-1]
    report["moved_revision"] = moved
    report["answer"] = answers[-1]
    wait_written(link, moved, photons)
    light = bpy.data.objects[ies_light.LIGHT_NAME]
    report["light_location"] = list(light.matrix_world.translation)
    report["light_energy"] = light.data.energy
    if do_render:
        report["render_before"] = render(scene,
                                         os.path.join(out, "blender_room_reflector_092.png"))

    # the reflector's specular reflectance: one set delta, a new result, a new light
    reflector = by_prim(bpy.data.materials, REFLECTOR)
    reflector[SPEC] = 0.5
    clock.now += 0.05
    link.poll()
    clock.now += live.DEBOUNCE + 0.01
    report["reflector_answer"] = link.poll()
    edited = link.sent_revisions[-1]
    wait_written(link, edited, photons)
    report["edited_revision"] = edited
    report["batches"] = [list(b) for b in link.batches]
    text = bpy.data.objects[ies_light.LIGHT_NAME].data.node_tree.nodes["lumitrace IES"].ies
    report["light_ies_sha256"] = hashlib.sha256(text.as_string().encode()).hexdigest()
    report["light_revision"] = link.light_revision
    with open(os.path.join(out, "light.ies"), "w") as f:
        f.write(text.as_string())
    if do_render:
        report["render_after"] = render(scene,
                                        os.path.join(out, "blender_room_reflector_050.png"))
    report["error"] = link.error
    report["panel"] = panel_text(scene)
    assert bpy.ops.lumitrace.disconnect() == {"FINISHED"}
    return report


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("url")
    parser.add_argument("stage")
    parser.add_argument("--out", required=True)
    parser.add_argument("--photons", type=int, default=2_000_000,
                        help="the service's photon budget (default: its own, 2e6)")
    parser.add_argument("--render", default=None, help="render the room: WIDTHxHEIGHT")
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--denoise", action="store_true")
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    a = parser.parse_args(argv)
    size = tuple(int(v) for v in a.render.split("x")) if a.render else None
    print(json.dumps(main(a.url, os.path.abspath(a.stage), os.path.abspath(a.out), a.photons,
                          size, a.samples, a.denoise)))
