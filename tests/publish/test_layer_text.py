"""The result layer's text, written and read back without USD
(lumitrace.publish.layer_text), against USD's own authoring API and parser."""
from __future__ import annotations

import math
import subprocess
import sys

import pytest

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)
from lumitrace.publish import layer_text
from lumitrace.publish.layer_text import PHOTOMETRIC_LIGHT, REPRESENTATION
from lumitrace.schema import (EMITTER_API, LUMINAIRE_API, LUMINOUS_FLUX, RESULT_KINDS,
                              RESULT_PREFIX)
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux

_SDF_TYPES = {"asset": Sdf.ValueTypeNames.Asset, "int64": Sdf.ValueTypeNames.Int64,
              "int": Sdf.ValueTypeNames.Int, "double": Sdf.ValueTypeNames.Double,
              "bool": Sdf.ValueTypeNames.Bool, "string": Sdf.ValueTypeNames.String}


def usd_authored(prim_path: str, values: dict, light: dict | None, layer_data: dict | None,
                 units, documentation: str) -> Sdf.Layer:
    """The same result layer authored through USD's API (Sdf specs, the Usd stage's
    variant edit context, UsdLux's DiskLight and ShapingAPI): the reference."""
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.documentation = documentation
    if layer_data:
        layer.customLayerData = {f"lumitrace:{k}": str(v) for k, v in layer_data.items()}
    path = Sdf.Path(prim_path)
    spec = Sdf.CreatePrimInLayer(layer, path)
    spec.specifier = Sdf.SpecifierOver
    if path.IsRootPrimPath():
        layer.defaultPrim = path.name
    if units is not None:
        layer.pseudoRoot.SetInfo(UsdGeom.Tokens.upAxis, units[0])
        layer.pseudoRoot.SetInfo(UsdGeom.Tokens.metersPerUnit, float(units[1]))
    spec.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=[LUMINAIRE_API]))
    for key, value in values.items():
        attr = Sdf.AttributeSpec(spec, RESULT_PREFIX + key, _SDF_TYPES[RESULT_KINDS[key]],
                                 Sdf.VariabilityVarying, declaresCustom=False)
        attr.default = Sdf.AssetPath(value) if RESULT_KINDS[key] == "asset" else value
    if light is None:
        return layer
    stage = Usd.Stage.Open(layer)
    vset = stage.OverridePrim(path).GetVariantSets().AddVariantSet(REPRESENTATION)
    vset.AddVariant("geometry")
    vset.AddVariant("photometric")
    vset.SetVariantSelection("photometric")
    with vset.GetVariantEditContext():
        disk = UsdLux.DiskLight.Define(stage, path.AppendChild(PHOTOMETRIC_LIGHT))
        disk.CreateRadiusAttr(float(light["radius"]))
        disk.CreateNormalizeAttr(True)
        disk.CreateIntensityAttr(light["flux"] / math.pi)
        p = disk.GetPrim()
        p.AddAppliedSchema(EMITTER_API)
        p.CreateAttribute(LUMINOUS_FLUX, Sdf.ValueTypeNames.Float).Set(light["flux"])
        shaping = UsdLux.ShapingAPI.Apply(p)
        shaping.CreateShapingIesFileAttr(Sdf.AssetPath(light["ies"]))
        shaping.CreateShapingIesNormalizeAttr(True)
        xf = UsdGeom.Xformable(p)
        xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*light["position"]))
        if light.get("up_axis", "Z") == "Y":
            xf.AddRotateXOp().Set(-90.0)
    target = vset.GetVariantEditTarget()
    for emitter in light.get("emitters", ()):
        Sdf.CreatePrimInLayer(layer, target.MapToSpecPath(Sdf.Path(emitter))).active = False
    vset.SetVariantSelection("geometry")
    # USD's Define makes a nested luminaire's undefined ancestors ``def``; a result layer
    # only overrides what the stage defines
    for parent in path.GetParentPath().GetPrefixes():
        layer.GetPrimAtPath(parent).specifier = Sdf.SpecifierOver
    return layer


def _values() -> dict:
    values = {}
    for i, (key, kind) in enumerate(RESULT_KINDS.items()):
        values[key] = {"asset": f"./out/{key} @x.exr" if i % 2 else f"../{key}.ies",
                       "int64": 2**62 + i, "int": -2**31 + i, "bool": bool(i % 2),
                       "string": f'{key} "quoted" \\ é\nline\ttab\x01',
                       "double": [math.pi * 1e-300, -0.0, 5.107e-06, 1e22, math.inf,
                                  -math.inf, 121.02544346086034, 3.0][i % 8]}[kind]
    return values


CASES = {
    "full, Z up": ("/Luminaire", _values(),
                   {"ies": "./a.ies", "flux": 1234.5678, "radius": 0.049667507123,
                    "position": (-5.107e-06, 1.1567836e-05, 0.0), "up_axis": "Z",
                    "emitters": ["/Luminaire/Source", "/Luminaire/Board/LED_0001",
                                 "/Luminaire/Board/LED_0002", "/Luminaire/Board"]},
                   {"runId": "5d07", "stage": "../s/a b.usda", "files": '{"a": "b\'c"}'},
                   ("Z", 0.01)),
    "nested prim, Y up, no emitters": ("/World/Lamp", {"photons": 12, "converged": False},
                                       {"ies": "./w@w.ies", "flux": 1e-3, "radius": 2.0,
                                        "position": (1.0, 2.0, 3.0), "up_axis": "Y"},
                                       None, ("Y", 1.0)),
    "no light, no units": ("/L", {"relativeError": float("nan")}, None, {"runId": "r"}, None),
}


def _export(layer: Sdf.Layer) -> str:
    return layer.ExportToString()


@pytest.mark.parametrize("case", list(CASES))
def test_the_text_is_the_layer_usd_authors(case):
    """USD parses our text into the layer its own API authors from the same values:
    the same specs, fields and values (NaN included), exported alike."""
    prim, values, light, data, units = CASES[case]
    text = layer_text.result_layer_text(prim, values, light, data, units, "doc \"x\"\nend")
    ours = Sdf.Layer.CreateAnonymous(".usda")
    assert ours.ImportFromString(text)
    reference = usd_authored(prim, values, light, data, units, "doc \"x\"\nend")
    assert _export(ours) == _export(reference)
    # the composed luminaire too: its result attributes, and the stand-in light when asked
    stage = Usd.Stage.Open(ours)
    lum = stage.GetPrimAtPath(prim)
    assert lum.HasAPI(LUMINAIRE_API)
    for key, value in values.items():
        got = lum.GetAttribute(RESULT_PREFIX + key).Get()
        got = got.path if isinstance(got, Sdf.AssetPath) else got
        assert got == value or (got != got and value != value), key


def test_floats_are_what_usd_rounds_a_double_to():
    """A light's float attributes hold USD's own rounding of the double given, whatever
    numpy's print options are."""
    import numpy as np

    before = np.get_printoptions()
    np.set_printoptions(precision=3)
    try:
        _floats_round_as_usd_does()
    finally:
        np.set_printoptions(**before)


def _floats_round_as_usd_does():
    for flux in (1.0 / 3.0, 1e-7, 3.4e38, 123456789.123, 1e-45, 392.97513, 0.1):
        light = {"ies": "./a.ies", "flux": flux, "radius": flux, "position": (0, 0, 0)}
        ours = Sdf.Layer.CreateAnonymous(".usda")
        assert ours.ImportFromString(layer_text.result_layer_text(
            "/L", {}, light, None, None, "d"))
        assert _export(ours) == _export(usd_authored("/L", {}, light, None, None, "d"))


def _data_by_usd(path) -> dict:
    return dict(Sdf.Layer.OpenAsAnonymous(str(path), metadataOnly=True).customLayerData)


def test_custom_data_reads_back_as_usd_reads_it(tmp_path):
    """Our layer, and the same layer saved again by USD (which quotes and orders its own
    way), read back to USD's customLayerData."""
    prim, values, light, data, units = CASES["full, Z up"]
    data = {**data, "odd": "tab\t nl\n quote\" apos' back\\ é \x7f"}
    ours = tmp_path / "ours.usda"
    ours.write_text(layer_text.result_layer_text(prim, values, light, data, units, "d"),
                    encoding="utf-8")
    resaved = tmp_path / "resaved.usda"
    Sdf.Layer.FindOrOpen(str(ours)).Export(str(resaved))
    assert resaved.read_text(encoding="utf-8") != ours.read_text(encoding="utf-8")
    for path in (ours, resaved):
        assert layer_text.custom_layer_data(path) == _data_by_usd(path)
        assert layer_text.custom_layer_data(path)["lumitrace:odd"] == data["odd"]


@pytest.mark.parametrize("header, expected", [
    ('(\n    doc = "x ) { customLayerData"\n    # customLayerData = { no }\n)\n', {}),
    ('(\n    customLayerData = {\n        # a comment\n        string "a" = "1"\n'
     '        string \'b\' = """two\nlines"""\n    }\n    upAxis = "Y"\n)\n',
     {"a": "1", "b": "two\nlines"}),
    ('(\n    customLayerData = {\n        int "n" = 3\n    }\n)\n', None),
    ('(\n    customLayerData = {\n        dictionary "d" = {\n            string "a" = "b"\n'
     '        }\n    }\n)\n', None),
    ('(\n    customLayerData = {\n        string "a" = "\\xe9"\n    }\n)\n', None),
    # said twice (USD takes the last), or in a version of the format not read here
    ('(\n    customLayerData = {\n        string "a" = "1"\n    }\n'
     '    customLayerData = {\n        string "a" = "2"\n    }\n)\n', None),
    ('(\n    customLayerData = {\n        string "a" = "1";\n    }\n)\n', None),
])
def test_custom_data_is_read_or_left_to_usd(tmp_path, header, expected):
    """What the reader is sure of equals USD's reading; any other form is None (USD is
    asked instead), never a wrong value."""
    path = tmp_path / "l.usda"
    path.write_text("#usda 1.0\n" + header + "\ndef \"P\"\n{\n}\n", encoding="utf-8")
    got = layer_text.custom_layer_data(path)
    assert got == expected
    if got is not None:
        assert got == _data_by_usd(path)


def test_a_header_of_another_version_is_left_to_usd(tmp_path):
    path = tmp_path / "l.usda"
    path.write_text('#usda 9.9\n(\n    customLayerData = {\n        string "a" = "1"\n'
                    '    }\n)\n', encoding="utf-8")
    assert layer_text.custom_layer_data(path) is None


def test_a_layer_that_is_not_text_is_left_to_usd(tmp_path):
    crate = tmp_path / "l.usdc"
    layer = Sdf.Layer.CreateNew(str(crate))
    layer.customLayerData = {"lumitrace:runId": "x"}
    layer.Save()
    assert layer_text.custom_layer_data(crate) is None
    assert layer_text.custom_layer_data(tmp_path / "missing.usda") is None


def test_writing_and_reading_the_layer_text_loads_no_usd(tmp_path):
    """The point of the module: a fresh interpreter writes and reads it with pxr never
    imported."""
    code = (
        "import sys, pathlib\n"
        "from lumitrace.publish import layer_text\n"
        "p = pathlib.Path(sys.argv[1])\n"
        "p.write_text(layer_text.result_layer_text('/L', {'photons': 3}, {'ies': './a.ies',"
        " 'flux': 1.0, 'radius': 1.0, 'position': (0, 0, 0)}, {'runId': 'r'}, ('Z', 1.0),"
        " 'd'))\n"
        "assert layer_text.custom_layer_data(p) == {'lumitrace:runId': 'r'}\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'pxr'))\n")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "l.usda")],
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_a_luminaire_that_is_its_light_keeps_its_stand_in():
    """Where the luminaire prim is the light itself, nothing under it is switched off in the
    photometric variant (USD's authoring would deactivate the variant's own prim, stand-in
    light and all); an emitter outside the luminaire is an error, not a silent spec."""
    light = {"ies": "./a.ies", "flux": 1.0, "radius": 1.0, "position": (0, 0, 0),
             "emitters": ["/Led"]}
    layer = Sdf.Layer.CreateAnonymous(".usda")
    assert layer.ImportFromString(layer_text.result_layer_text("/Led", {}, light, None,
                                                               None, "d"))
    stage = Usd.Stage.Open(layer)
    prim = stage.GetPrimAtPath("/Led")
    prim.GetVariantSets().SetSelection(REPRESENTATION, "photometric")
    assert prim.IsActive()
    assert stage.GetPrimAtPath(f"/Led/{PHOTOMETRIC_LIGHT}").IsActive()
    with pytest.raises(ValueError, match="not under the luminaire"):
        layer_text.result_layer_text("/Led", {}, {**light, "emitters": ["/Other"]}, None,
                                     None, "d")


_SUBLAYERED = [
    '#usda 1.0\n(\n    subLayers = [\n        @./out/a.lumitrace.usda@,\n        @parts.usda@\n    ]\n)\n',
    '#usda 1.0\n# a comment\n\n(\n  doc = "(subLayers = [@x@])"\n  subLayers = [@a.usda@, @b c.usda@ ]\n)\n',
    '#usda 1.0\n(\n    subLayers = []\n)\ndef Xform "X" {}\n',
    '#usda 1.0\n(\n    doc = "none"\n)\n',
    '#usda 1.0\ndef Xform "X" {\n}\n',
    '#usda 1.0\n(\n    subLayers = [@a.usda@ (offset = 2; scale = 1), @b.usda@]\n)\n',
    '#usda 1.0\n(\n    subLayers = [\n        @a.usda@,  # first\n        @b.usda@\n    ]\n)\n',
    '#usda 1.0\n(\n    subLayers = [@@@odd@name.usda@@@]\n)\n',
]


@pytest.mark.parametrize("text", _SUBLAYERED)
def test_sublayers_read_from_text_are_what_usd_reads_or_left_to_it(text):
    from lumitrace.publish.usda_text import sublayer_entries

    layer = Sdf.Layer.CreateAnonymous(".usda")
    assert layer.ImportFromString(text)
    entries = sublayer_entries(text)
    assert entries is None or entries == list(layer.subLayerPaths)
    plain = _SUBLAYERED.index(text) < 5  # the others carry offsets, comments, @@@ paths
    assert (entries is not None) == plain


def test_a_root_layer_may_hold_results_unless_its_text_never_names_them(tmp_path):
    from lumitrace.publish.check import may_hold_results

    clean, flattened, crate = (tmp_path / n for n in ("a.usda", "b.usda", "c.usdc"))
    clean.write_text('#usda 1.0\ndef Xform "Luminaire" {\n    double lumitrace:x = 1\n}\n')
    flattened.write_text('#usda 1.0\nover "Luminaire" {\n    int64 lumitrace:result:photons'
                         ' = 5\n}\n')
    Sdf.Layer.FindOrOpen(str(clean)).Export(str(crate))
    assert not may_hold_results(clean)
    assert may_hold_results(flattened) and may_hold_results(crate)
    assert may_hold_results(tmp_path / "missing.usda")
