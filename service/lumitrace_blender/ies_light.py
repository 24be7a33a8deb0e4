"""The luminaire's traced distribution as a Blender light: a point light whose strength
follows lumitrace's IES file, placed and turned as the luminaire is, so Cycles renders a
room lit by the luminaire's measured-equivalent candela.

Calibration: Cycles reads IES candela as watts per steradian through its fixed D65
efficacy (candela times 4 pi / 177.83, then 1 / (4 pi) for a point light), so a light of
1 W gives I / 177.83 W/sr in metres. A scene whose unit is ``scale_length`` metres needs
``1 / scale_length^2`` W for the same irradiance: :func:`light_energy`.

Orientation: lumitrace's IES has C = 0 along the luminaire's +X and C = 90 along +Y (C
counter-clockwise seen from above), gamma = 0 at nadir (-Z). Cycles looks IES files up
with C = 0 along the light's -Y and C = 90 along its -X (the other hand), so the IES
texture's vector is mirrored and turned by a Mapping node (scale -1 in x, then 90 deg
about z): the light's own axes are then the luminaire's photometric frame.
"""
from __future__ import annotations

import math

import bpy

from . import records

LIGHT_NAME = "lumitrace photometric light"
#: Mapping node (scale, rotation in radians) from the photometric frame to Cycles' IES one.
CYCLES_IES_SCALE = (-1.0, 1.0, 1.0)
CYCLES_IES_ROTATION = (0.0, 0.0, math.pi / 2)


def light_energy(scene) -> float:
    """Watts of the IES point light for physical irradiance in ``scene``'s units."""
    unit = scene.unit_settings.scale_length if scene.unit_settings.system != "NONE" else 1.0
    return 1.0 / (unit * unit)


def ies_light(scene, name: str = LIGHT_NAME):
    """The add-on's IES light in ``scene`` (made on first use): ``(object, text)``."""
    obj = bpy.data.objects.get(name)
    if obj is None or obj.type != "LIGHT":
        data = bpy.data.lights.new(name, "POINT")
        obj = bpy.data.objects.new(name, data)
        obj[records.LIVE_KEY] = True
        scene.collection.objects.link(obj)
    elif obj.name not in scene.objects:
        scene.collection.objects.link(obj)
    light = obj.data
    light.shadow_soft_size = 0.0
    light.use_nodes = True
    light[records.LIVE_KEY] = True
    nodes, links = light.node_tree.nodes, light.node_tree.links
    ies = nodes.get("lumitrace IES")
    if ies is None:
        for node in list(nodes):
            if node.bl_idname not in ("ShaderNodeOutputLight",):
                nodes.remove(node)
        out = nodes.get("Light Output") or nodes.new("ShaderNodeOutputLight")
        emission = nodes.new("ShaderNodeEmission")
        ies = nodes.new("ShaderNodeTexIES")
        ies.name = "lumitrace IES"
        geometry = nodes.new("ShaderNodeNewGeometry")
        to_object = nodes.new("ShaderNodeVectorTransform")
        to_object.vector_type, to_object.convert_from, to_object.convert_to = \
            "NORMAL", "WORLD", "OBJECT"
        mapping = nodes.new("ShaderNodeMapping")
        mapping.name = "lumitrace frame"
        mapping.vector_type = "VECTOR"
        mapping.inputs["Scale"].default_value = CYCLES_IES_SCALE
        mapping.inputs["Rotation"].default_value = CYCLES_IES_ROTATION
        links.new(geometry.outputs["Normal"], to_object.inputs[0])
        links.new(to_object.outputs[0], mapping.inputs["Vector"])
        links.new(mapping.outputs[0], ies.inputs["Vector"])
        links.new(ies.outputs["Fac"], emission.inputs["Strength"])
        links.new(emission.outputs[0], out.inputs["Surface"])
    text = ies.ies
    if text is None:
        text = bpy.data.texts.new(name + ".ies")
        text[records.LIVE_KEY] = True
        ies.mode = "INTERNAL"
        ies.ies = text
    light.energy = light_energy(scene)
    return obj, text


def show_ies(scene, ies_text: str, world_matrix, name: str = LIGHT_NAME):
    """Put ``ies_text`` (an IES LM-63 file's text) into the light and place it at
    ``world_matrix`` (its axes the photometric frame: +X C0, +Y C90, -Z nadir)."""
    obj, text = ies_light(scene, name)
    text.clear()
    text.write(ies_text)
    obj.matrix_world = world_matrix
    obj.data.node_tree.nodes["lumitrace IES"].ies = text  # tags the light for a re-render
    obj.data.update_tag()
    return obj
