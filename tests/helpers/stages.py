"""Small luminaire stages built in tests, and reading them back."""
from __future__ import annotations

import pytest
from pxr import Gf, Usd, UsdGeom, UsdLux

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)
from lumitrace.errors import StageError
from lumitrace.scene import Scene
from lumitrace.stage import read_stage

QUAD = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]


def new_stage(tmp_path, name="luminaire.usda", meters_per_unit=1.0, up_axis="Z"):
    stage = Usd.Stage.CreateNew(str(tmp_path / name))
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    UsdGeom.SetStageUpAxis(stage, up_axis)
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(root.GetPrim())
    return stage


def add_mesh(stage, path, points=QUAD, counts=(4,), indices=(0, 1, 2, 3), scale=1.0):
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([Gf.Vec3f(*(scale * c for c in p)) for p in points])
    mesh.CreateFaceVertexCountsAttr(list(counts))
    mesh.CreateFaceVertexIndicesAttr(list(indices))
    return mesh


def add_disk(stage, path="/Luminaire/Led", flux=1000.0, radius=0.05):
    light = UsdLux.DiskLight.Define(stage, path)
    light.CreateRadiusAttr(radius)
    if flux is not None:
        light.GetPrim().ApplyAPI("LumitraceEmitterAPI")
        light.GetPrim().GetAttribute("lumitrace:luminousFlux").Set(flux)
    return light


def read(stage, **kwargs) -> Scene:
    stage.Save()
    return read_stage(stage.GetRootLayer().realPath, **kwargs)


def expect_error(stage, *fragments, **kwargs):
    with pytest.raises(StageError) as info:
        read(stage, **kwargs)
    message = str(info.value)
    for fragment in fragments:
        assert fragment in message, message
    return message


def with_attributes(src, dst, attributes: dict):
    """A copy of stage ``src`` at ``dst`` with ``attributes`` ({name: (Sdf type name in
    lower case, value)}) authored on its default prim (the luminaire's own data)."""
    import shutil

    from pxr import Sdf

    shutil.copy(src, dst)
    stage = Usd.Stage.Open(str(dst))
    prim = stage.GetDefaultPrim()
    for name, (kind, value) in attributes.items():
        prim.CreateAttribute(name, getattr(Sdf.ValueTypeNames, kind.capitalize())).Set(value)
    stage.GetRootLayer().Save()
    return dst
