"""A stage read again with what the last read made (as the service reads it after every
edit) gives the scene a read afresh gives, array for array, after edits of every kind; and
what an edit leaves alone is taken again, not made anew."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, UsdGeom
from stress_cases import FOUR_PARTS, four_part_luminaire

from lumitrace.stage.reader import scene_from_stage
from lumitrace.stage.reuse import ReadCache

PARTS = FOUR_PARTS


@pytest.fixture
def stage(tmp_path):
    return four_part_luminaire(tmp_path / "lum.usda")


def _same_scene(a, b) -> None:
    for name in ("triangles", "material_index", "part_index"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.parts == b.parts and a.materials == b.materials and a.warnings == b.warnings
    assert a.content_hash() == b.content_hash()
    for fa, fb in zip(a.part_frames, b.part_frames, strict=True):
        assert (fa is None) == (fb is None)
        if fa is not None:
            for name in ("local", "linear", "offset"):
                np.testing.assert_array_equal(getattr(fa, name), getattr(fb, name))


def _edit(stage, kind: str) -> None:
    prim = stage.GetPrimAtPath(PARTS[0])
    if kind == "material":  # (the material is applied to the gprim itself)
        prim.GetAttribute("lumitrace:specularReflectance").Set(0.5)
    elif kind == "move":
        UsdGeom.Xformable(prim).AddTranslateOp(opSuffix="edit").Set(Gf.Vec3d(0, 0.002, 0))
    elif kind == "mirror":
        UsdGeom.Xformable(stage.GetPrimAtPath(PARTS[2])).AddScaleOp(opSuffix="m").Set(
            Gf.Vec3f(-1.0, 1.0, 1.0))
    elif kind == "points":
        mesh = UsdGeom.Mesh(prim)
        mesh.GetPointsAttr().Set([p * 1.1 for p in mesh.GetPointsAttr().Get()])
    elif kind == "orientation":
        UsdGeom.Mesh(prim).GetOrientationAttr().Set(UsdGeom.Tokens.leftHanded)
    elif kind == "lens to diffuse":  # a dielectric no more: its faces are not turned
        stage.GetPrimAtPath(PARTS[1]).GetAttribute("lumitrace:scattering").Set("diffuse")
    elif kind == "deactivate":
        stage.GetPrimAtPath(PARTS[2]).SetActive(False)


def test_a_read_that_reuses_gives_a_fresh_reads_scene_after_every_edit(stage):
    cache = ReadCache()
    _same_scene(scene_from_stage(stage, cache=cache), scene_from_stage(stage))
    for kind in ("material", "move", "mirror", "points", "orientation", "lens to diffuse",
                 "deactivate"):
        _edit(stage, kind)
        _same_scene(scene_from_stage(stage, cache=cache), scene_from_stage(stage))


def test_what_an_edit_leaves_alone_is_taken_again(stage):
    cache = ReadCache()
    scene_from_stage(stage, cache=cache)
    board = cache._placed[PARTS[2]].world
    reflector = cache._triangulated[PARTS[0]].triangles
    _edit(stage, "move")  # the reflector placed anew, its own triangles and the board kept
    scene_from_stage(stage, cache=cache)
    assert cache._placed[PARTS[2]].world is board
    assert cache._triangulated[PARTS[0]].triangles is reflector
    assert cache._placed[PARTS[0]].local is reflector
    _edit(stage, "points")  # the reflector triangulated anew
    scene_from_stage(stage, cache=cache)
    assert cache._triangulated[PARTS[0]].triangles is not reflector
    _edit(stage, "deactivate")  # a prim no longer read is forgotten
    scene_from_stage(stage, cache=cache)
    assert PARTS[2] not in cache._placed and PARTS[2] not in cache._triangulated
