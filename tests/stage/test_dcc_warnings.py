"""Stages as DCCs write them: a lossless PreviewSurface and a subdivision surface are traced,
each with one warning naming the prim, the property and the value used."""
from __future__ import annotations

import shutil

from pxr import Sdf, Usd

from lumitrace.stage.reader import read_stage
from helpers.paths import DATA


def test_a_white_metal_preview_surface_is_a_lossless_mirror_and_says_so(tmp_path):
    stage = tmp_path / "chrome.usda"
    shutil.copy(DATA / "chrome_preview.usda", stage)
    scene = read_stage(stage)
    (mat,) = scene.materials
    assert (mat.scattering, mat.specular_reflectance) == ("mirror", 1.0)
    lossless = [w for w in scene.warnings if "absorbs no light" in w]
    assert len(lossless) == 1
    assert lossless[0].startswith("/Luminaire/Chrome/Shader.inputs:diffuseColor")
    assert "reflectance 1.000" in lossless[0]
    cage = [w for w in scene.warnings if "control cage" in w]
    assert len(cage) == 1 and cage[0].startswith("/Luminaire/Reflector")


def test_the_lumitrace_value_silences_the_warning(tmp_path):
    stage_path = tmp_path / "chrome.usda"
    shutil.copy(DATA / "chrome_preview.usda", stage_path)
    stage = Usd.Stage.Open(str(stage_path))
    mat = stage.GetPrimAtPath("/Luminaire/Chrome")
    mat.AddAppliedSchema("LumitraceMaterialAPI")
    mat.CreateAttribute("lumitrace:specularReflectance", Sdf.ValueTypeNames.Float).Set(0.92)
    stage.GetPrimAtPath("/Luminaire/Reflector").GetAttribute("subdivisionScheme").Set("none")
    stage.GetRootLayer().Save()
    scene = read_stage(stage_path)
    assert scene.materials[0].specular_reflectance == 0.92 or \
        abs(scene.materials[0].specular_reflectance - 0.92) < 1e-6
    assert not [w for w in scene.warnings if "absorbs no light" in w or "cage" in w]
