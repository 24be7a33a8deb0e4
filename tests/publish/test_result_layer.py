"""The result layer beside the stage (lumitrace.publish.result_layer)."""
from __future__ import annotations

import os
import shutil
import stat
from pathlib import Path

import pytest

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)
from lumitrace import atomic
from lumitrace.publish import sublayer
from lumitrace.errors import OutputError
from lumitrace.report.references import read_expectation
from lumitrace.publish import result_layer as writer
from lumitrace.publish.result_layer import (RESULT_KINDS, ResultLayerWarning, result_layer_path,
                                    write_result_layer)
from pxr import Sdf, Usd, UsdGeom, UsdUtils
from helpers.paths import STAGES


TYPES = {"asset": "asset", "int64": "int64", "int": "int", "double": "double",
         "bool": "bool", "string": "string"}


def full_results(folder: Path, photons: int = 1_000_000) -> dict:
    out = folder / "out"
    out.mkdir(exist_ok=True)
    for name in ("stage.intensity.exr", "stage.ies", "stage.ldt", "stage.polar.png",
                 "stage.solid.png"):
        (out / name).write_bytes(b"x")
    return {
        "intensityMap": out / "stage.intensity.exr",      # absolute paths are made relative
        "latlongMap": out / "stage.latlong.exr",
        "iesFile": str(out / "stage.ies"),
        "ldtFile": "out/stage.ldt",                       # relative to the stage's folder
        "photons": photons,
        "iterations": 12,
        "elapsedSeconds": 3.25,
        "relativeError": 0.0125,
        "relativeErrorBound": 0.0175,
        "luminousFlux": 987.5,
        "lightOutputRatio": 0.9875,
        "threshold": 4.0,
        "resolution": 64,
        "seed": 42,
        "converged": True,
        "inputHash": "0123abcd",
        "downwardFluxFraction": 0.75,
        "peakIntensity": 321.5,
        "peakIntensityError": 2.5,
        "sceneHash": "0" * 64,
        "luminousFluxError": 0.75,
        "photometryError": 0.0125,
        "photometryData": out / "stage.photometry.json",
        "beamAngleC0": 60.5,
        "beamAngleC90": float("nan"),
        "fieldAngleC0": 100.25,
        "fieldAngleC90": 101.0,
        "cieFluxCode": "44 75 94 75 99",
        "symmetry": "quadrant",
        "symmetrySource": "geometry",
        "polarDiagram": out / "stage.polar.png",
        "photometricSolid": out / "stage.solid.png",
        "colourData": out / "stage.colour.json",
        "colourDiagram": out / "stage.colour.png",
        "cct": 2890.5,
        "duv": -0.0009,
        "colourUniformity": 0.0012,
        "ugr4H8H": 19.25,
        "ugr4H8HError": 0.125,
        "screenLuminanceMax": 1450.0,
        "bugRating": "B1 U0 G1",
        "datasheetHtml": out / "stage.datasheet.html",
        "datasheetPdf": out / "stage.datasheet.pdf",
        "gldfFile": out / "stage.gldf",
        "targetOf": "files",
        "judgedError": 0.0175,
    }


@pytest.fixture
def stage_copy(tmp_path):
    def copy(name: str = "reference/isotropic.usda") -> Path:
        dst = tmp_path / Path(name).name
        shutil.copyfile(STAGES / name, dst)
        return dst
    return copy


def snapshot(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


class Attr:
    """Type name and value of a composed attribute (outlives its stage)."""

    def __init__(self, attr: Usd.Attribute):
        self.type_name = str(attr.GetTypeName())
        self.value = attr.Get()

    def Get(self):
        return self.value


def result_attrs(stage_path: Path, prim: str = "/Luminaire") -> dict:
    """The authored lumitrace:result:* attributes of the prim, by suffix, composed from a
    freshly opened stage."""
    stage = Usd.Stage.Open(str(stage_path))
    p = stage.GetPrimAtPath(prim)
    return {a.GetName().split(":")[-1]: Attr(a) for a in p.GetAttributes()
            if a.GetName().startswith("lumitrace:result:") and a.HasAuthoredValue()}


def test_attributes_have_the_contract_types(stage_copy):
    stage_path = stage_copy()
    results = full_results(stage_path.parent, photons=10_000_000_000)
    layer = write_result_layer(stage_path, "/Luminaire", results)
    assert layer == stage_path.with_name("isotropic.lumitrace.usda") == \
        result_layer_path(stage_path)

    stage = Usd.Stage.Open(str(stage_path))
    prim = stage.GetPrimAtPath("/Luminaire")
    assert "LumitraceLuminaireAPI" in prim.GetAppliedSchemas()
    attrs = result_attrs(stage_path)
    assert set(attrs) == set(RESULT_KINDS)
    for key, kind in RESULT_KINDS.items():
        assert attrs[key].type_name == TYPES[kind], key
    assert attrs["photons"].Get() == 10_000_000_000
    assert attrs["iterations"].Get() == 12
    assert attrs["resolution"].Get() == 64 and attrs["seed"].Get() == 42
    assert attrs["elapsedSeconds"].Get() == 3.25
    assert attrs["relativeError"].Get() == 0.0125
    assert attrs["luminousFlux"].Get() == 987.5
    assert attrs["lightOutputRatio"].Get() == 0.9875
    assert attrs["threshold"].Get() == 4.0
    assert attrs["converged"].Get() is True
    assert attrs["inputHash"].Get() == "0123abcd"
    for key, name in (("intensityMap", "stage.intensity.exr"), ("iesFile", "stage.ies"),
                      ("ldtFile", "stage.ldt")):
        asset = attrs[key].Get()
        assert asset.path == f"./out/{name}"
        assert Path(asset.resolvedPath) == stage_path.parent / "out" / name
    # the sublayer entry is relative, at the front
    root = Sdf.Layer.OpenAsAnonymous(str(stage_path))
    assert list(root.subLayerPaths) == ["./isotropic.lumitrace.usda"]


def test_second_write_keeps_one_entry_and_the_new_values(stage_copy):
    stage_path = stage_copy()
    write_result_layer(stage_path, "/Luminaire", full_results(stage_path.parent))
    root_after_first = stage_path.read_bytes()
    write_result_layer(stage_path, "/Luminaire",
                       {"photons": 5, "converged": False, "relativeError": float("inf")})
    assert stage_path.read_bytes() == root_after_first        # the root is not touched again
    root = Sdf.Layer.OpenAsAnonymous(str(stage_path))
    assert list(root.subLayerPaths) == ["./isotropic.lumitrace.usda"]
    attrs = result_attrs(stage_path)
    assert set(attrs) == {"photons", "converged", "relativeError"}
    assert attrs["photons"].Get() == 5
    assert attrs["converged"].Get() is False
    assert attrs["relativeError"].Get() == float("inf")


def test_original_content_is_preserved(stage_copy):
    stage_path = stage_copy("reference/fresnel_slab.usda")
    before = Sdf.Layer.OpenAsAnonymous(str(stage_path))
    expectation = read_expectation(stage_path)
    stage_before = Usd.Stage.Open(before)
    prims_before = [str(p.GetPath()) for p in stage_before.Traverse()]
    write_result_layer(stage_path, "/Luminaire", full_results(stage_path.parent))

    after = Sdf.Layer.OpenAsAnonymous(str(stage_path))
    assert read_expectation(stage_path) == expectation
    assert after.defaultPrim == "Luminaire"
    stage = Usd.Stage.Open(str(stage_path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    assert [str(p.GetPath()) for p in stage.Traverse()] == prims_before
    assert stage.GetPrimAtPath("/Luminaire/Materials/Glass") \
        .GetAttribute("lumitrace:ior").Get() == pytest.approx(1.5)
    # apart from the sublayer entry, the layer is the same
    del after.subLayerPaths[0]
    assert after.ExportToString() == before.ExportToString()


COMMENTED = """#usda 1.0
# A hand-written stage: these comments must survive.
(
    # layer metadata
    doc = "has (parentheses) and subLayers = [ in a string"
    customLayerData = {
        string subLayers = "not the layer's sublayers"
    }
    defaultPrim = "Lamp"
    metersPerUnit = 0.01
    subLayers = [
        @./base.usda@ (offset = 2)
    ]
    upAxis = "Z"
)

# the luminaire
def Xform "Lamp"
{
    def SphereLight "Bulb" (  # a bulb
        prepend apiSchemas = ["LumitraceEmitterAPI"]
    )
    {
        float lumitrace:luminousFlux = 800  # lm
    }
}
"""


def test_text_root_keeps_comments_and_formatting(tmp_path):
    (tmp_path / "base.usda").write_text('#usda 1.0\n\nover "Lamp" {\n    int base = 1\n}\n')
    stage_path = tmp_path / "lamp.usda"
    stage_path.write_text(COMMENTED)
    write_result_layer(stage_path, None, {"photons": 7})       # None: the default prim
    text = stage_path.read_text()
    added = set(text.splitlines()) - set(COMMENTED.splitlines())
    assert [line.strip() for line in added] == ["@./lamp.lumitrace.usda@,"]
    assert text.replace("        @./lamp.lumitrace.usda@,\n", "") == COMMENTED
    root = Sdf.Layer.OpenAsAnonymous(str(stage_path))
    assert list(root.subLayerPaths) == ["./lamp.lumitrace.usda", "./base.usda"]
    assert root.subLayerOffsets[1].offset == 2
    assert root.customLayerData == {"subLayers": "not the layer's sublayers"}
    attrs = result_attrs(stage_path, "/Lamp")
    assert attrs["photons"].Get() == 7
    assert Usd.Stage.Open(str(stage_path)).GetPrimAtPath("/Lamp") \
        .GetAttribute("base").Get() == 1


@pytest.mark.parametrize("text", [
    '#usda 1.0\n\ndef Xform "Lamp"\n{\n}\n',                               # no metadata
    '#usda 1.0\n( defaultPrim = "Lamp" )\n\ndef Xform "Lamp"\n{\n}\n',     # one line
    '#usda 1.0\n(\n    subLayers = []\n)\n\ndef Xform "Lamp"\n{\n}\n',     # empty list
    '#usda 1.0\r\n(\r\n    doc = "crlf"\r\n)\r\n\r\ndef Xform "Lamp"\r\n{\r\n}\r\n',
    '#usda 1.0\n(\n    subLayers = [@base.usda@]\n)\n\ndef Xform "Lamp"\n{\n}\n',  # inline
])
def test_text_root_layouts(tmp_path, text):
    (tmp_path / "base.usda").write_text("#usda 1.0\n")
    stage_path = tmp_path / "lamp.usda"
    stage_path.write_bytes(text.encode())
    before = Sdf.Layer.OpenAsAnonymous(str(stage_path)).ExportToString()
    write_result_layer(stage_path, "/Lamp", {"seed": 3})
    after = Sdf.Layer.OpenAsAnonymous(str(stage_path))
    assert list(after.subLayerPaths)[0] == "./lamp.lumitrace.usda"
    del after.subLayerPaths[0]
    assert after.ExportToString() == before
    assert result_attrs(stage_path, "/Lamp")["seed"].Get() == 3


@pytest.mark.parametrize("bad, match", [
    ({"photonCount": 1}, "unknown"),
    ({"photons": "many"}, "integer"),
    ({"photons": -1}, "range"),
    ({"iterations": 1.5}, "integer"),
    ({"iterations": True}, "integer"),
    ({"seed": 2 ** 40}, "range"),
    ({"converged": 1}, "bool"),
    ({"elapsedSeconds": "1 s"}, "real"),
    ({"inputHash": 12}, "string"),
    ({"intensityMap": 3}, "path"),
])
def test_failing_write_leaves_files_untouched(stage_copy, bad, match):
    stage_path = stage_copy()
    write_result_layer(stage_path, "/Luminaire", full_results(stage_path.parent))
    before = snapshot(stage_path.parent)
    with pytest.raises(ValueError, match=match):
        write_result_layer(stage_path, "/Luminaire", {"photons": 99, **bad})
    assert snapshot(stage_path.parent) == before


def test_failing_first_write_writes_nothing(stage_copy):
    stage_path = stage_copy()
    before = snapshot(stage_path.parent)
    with pytest.raises(ValueError):
        write_result_layer(stage_path, "/Luminaire", {"bogus": 1})
    with pytest.raises(ValueError, match="prim path"):
        write_result_layer(stage_path, "Luminaire", {"photons": 1})
    with pytest.raises(ValueError, match="radius"):
        write_result_layer(stage_path, "/Luminaire", {"photons": 1}, light={"ies": "x.ies"})
    with pytest.raises(OutputError):
        write_result_layer(stage_path.with_name("missing.usda"), "/Luminaire", {"photons": 1})
    assert snapshot(stage_path.parent) == before


def test_crash_while_replacing_the_root_leaves_it_intact(stage_copy, monkeypatch):
    stage_path = stage_copy()
    before = stage_path.read_bytes()
    real_replace = os.replace

    def replace(src, dst):
        if Path(dst) == stage_path:
            raise OSError("disk full")
        real_replace(src, dst)

    def exchange(a, b):
        if Path(b) == stage_path:
            raise OSError("disk full")
        return False
    monkeypatch.setattr(atomic.os, "replace", replace)
    monkeypatch.setattr(sublayer, "_exchange", exchange)  # the swap that replaces a rename
    with pytest.raises(OutputError, match="disk full"):
        write_result_layer(stage_path, "/Luminaire", {"photons": 1})
    assert stage_path.read_bytes() == before
    assert sorted(p.name for p in stage_path.parent.iterdir()) == \
        ["isotropic.lumitrace.usda", "isotropic.usda"]          # no temporary files left


def test_file_mode_is_kept(stage_copy):
    stage_path = stage_copy()
    stage_path.chmod(0o640)
    write_result_layer(stage_path, "/Luminaire", {"photons": 1})
    assert stat.S_IMODE(stage_path.stat().st_mode) == 0o640
    assert stat.S_IMODE(result_layer_path(stage_path).stat().st_mode) == 0o640


def test_symlinked_stage_stays_a_symlink(stage_copy, tmp_path):
    real = stage_copy()
    link = tmp_path / "linked" / "isotropic.usda"
    link.parent.mkdir()
    link.symlink_to(real)
    write_result_layer(link, "/Luminaire", {"photons": 1})
    assert link.is_symlink()
    assert "./isotropic.lumitrace.usda" in real.read_text()


def test_usdc_root_is_sublayered_in_its_format(stage_copy):
    src = stage_copy()
    stage_path = src.with_suffix(".usdc")
    Sdf.Layer.FindOrOpen(str(src)).Export(str(stage_path))
    for path in (stage_path, stage_path.with_suffix(".usd")):
        if path.suffix == ".usd":
            shutil.copyfile(stage_path, path)
        write_result_layer(path, "/Luminaire", {"photons": 11})
        assert path.read_bytes().startswith(b"PXR-USDC")
        root = Sdf.Layer.OpenAsAnonymous(str(path))
        assert list(root.subLayerPaths) == ["./isotropic.lumitrace.usda"]
        assert read_expectation(path)["kind"] == "isotropic"
        assert result_attrs(path)["photons"].Get() == 11


def test_usdz_is_left_alone(stage_copy):
    src = stage_copy()
    package = src.with_suffix(".usdz")
    assert UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(src)), str(package))
    before = package.read_bytes()
    with pytest.warns(ResultLayerWarning, match="usdz"):
        layer = write_result_layer(package, "/Luminaire", {"photons": 1})
    assert package.read_bytes() == before
    assert layer == package.with_name("isotropic.lumitrace.usda") and layer.exists()


def test_read_only_root_is_left_alone(stage_copy, monkeypatch):
    stage_path = stage_copy()
    before = stage_path.read_bytes()
    monkeypatch.setattr(writer.os, "access", lambda path, mode: False)
    with pytest.warns(ResultLayerWarning, match="not writable"):
        layer = write_result_layer(stage_path, "/Luminaire", {"photons": 1})
    assert stage_path.read_bytes() == before
    assert layer.exists()


def test_open_stage_sees_the_results(stage_copy):
    stage_path = stage_copy()
    stage = Usd.Stage.Open(str(stage_path))
    prim = stage.GetPrimAtPath("/Luminaire")
    write_result_layer(stage_path, "/Luminaire", {"photons": 1})
    assert prim.GetAttribute("lumitrace:result:photons").Get() == 1
    write_result_layer(stage_path, "/Luminaire", {"photons": 2})
    assert prim.GetAttribute("lumitrace:result:photons").Get() == 2


def test_unsaved_edits_are_neither_saved_nor_lost(stage_copy):
    stage_path = stage_copy()
    stage = Usd.Stage.Open(str(stage_path))
    stage.GetPrimAtPath("/Luminaire/Source").GetAttribute("lumitrace:luminousFlux").Set(5.0)
    write_result_layer(stage_path, "/Luminaire", {"photons": 3})
    on_disk = Usd.Stage.Open(Sdf.Layer.OpenAsAnonymous(str(stage_path)))
    assert on_disk.GetPrimAtPath("/Luminaire/Source") \
        .GetAttribute("lumitrace:luminousFlux").Get() == 1000.0
    assert stage.GetPrimAtPath("/Luminaire/Source") \
        .GetAttribute("lumitrace:luminousFlux").Get() == 5.0
    assert stage.GetPrimAtPath("/Luminaire").GetAttribute("lumitrace:result:photons").Get() == 3
