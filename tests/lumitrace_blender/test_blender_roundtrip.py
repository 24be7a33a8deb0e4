"""The Blender add-on's import and export, run in a real Blender (bpy 4.5) and read back
by lumitrace: the demo edited in Blender traces as the original with the same edits sent
as deltas, and every stage survives an import and export unchanged."""
from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers.blender import blender_python, run_bpy
from helpers.paths import ROOT, STAGES

from lumitrace.delta.apply import apply_deltas
from lumitrace.delta.edits import open_edits_layer, open_with_edits, save_edits
from lumitrace.publish.exr import read_intensity_exr
from lumitrace.stage.reader import read_stage, scene_from_stage

DEMO = STAGES / "downlight.usda"
REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
SPEC = "lumitrace:specularReflectance"
#: The two edits of the round trip, as the scene-delta protocol says them.
DELTAS = [{"op": "transform", "path": "/Luminaire/Diffuser", "translate": [0, 0, -5]},
          {"op": "set", "path": REFLECTOR, "property": SPEC, "value": 0.5}]
ALL_STAGES = sorted(STAGES.glob("*.usda")) + sorted((STAGES / "reference").glob("*.usda"))


@pytest.fixture(scope="module")
def bpy_python():
    return blender_python()


def _trace(stage: Path, out: Path, seed: int, *extra) -> tuple[dict, np.ndarray]:
    p = subprocess.run([sys.executable, "-m", "lumitrace.cli", "trace", str(stage),
                        "--photons", "60000", "--resolution", "16", "--seed", str(seed),
                        "--threads", "2", "--no-progress", "--no-pictures", "--json",
                        "--no-sublayer", "--out", str(out), *map(str, extra)],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout.strip().splitlines()[-1])
    channels, _, _ = read_intensity_exr(summary["outputs"]["intensity_map"])
    return summary, channels["count"]


def _figures(summary: dict) -> dict[str, tuple[float, float]]:
    """Flux, LOR and peak with their standard errors."""
    ph = summary["photometry"]
    return {"flux": (ph["luminous_flux"], ph["luminous_flux_error"]),
            "lor": (summary["light_output_ratio"], summary["light_output_ratio_error"]),
            "peak": (ph["peak_intensity"], ph["peak_intensity_error"])}


def _deltas_applied(tmp_path: Path) -> tuple[Path, Path]:
    """A copy of the demo with the round trip's edits sent as deltas, in an edits layer
    as the service writes it."""
    folder = tmp_path / "deltas"
    folder.mkdir()
    stage = folder / "downlight.usda"
    shutil.copy(DEMO, stage)
    edits_path = folder / "downlight.lumitrace-edits.usda"
    layer = open_edits_layer(edits_path)
    apply_deltas(open_with_edits(stage, layer), layer, DELTAS, folder)
    save_edits(layer, 1)
    return stage, edits_path


def test_the_demo_edited_in_blender_traces_as_the_same_edits_sent_as_deltas(
        bpy_python, tmp_path):
    out = tmp_path / "blender"
    out.mkdir()
    stage = out / "downlight.usda"
    shutil.copy(DEMO, stage)
    report = run_bpy("roundtrip.py", "demo", stage, out)
    # the schema's values came in as ID properties with the schema's range as limits
    assert report["imported_value"] == pytest.approx(0.92, abs=1e-6)
    assert (report["ui"]["min"], report["ui"]["max"]) == (0.0, 1.0)
    assert report["diffuser_location"] == [0.0, 0.0, 0.0]
    # exactly the two edits, as opinions over the original on its own prim paths
    assert report["edits"] == [["transform", "/Luminaire/Diffuser", ""],
                               ["set", REFLECTOR, SPEC]]
    text = Path(report["exported"]).read_text()
    assert "@./downlight.usda@" in text and 'defaultPrim = "Luminaire"' in text
    assert 'def "' not in text and "metersPerUnit = 0.001" in text
    assert "float lumitrace:specularReflectance = 0.5" in text
    assert "(0, 0, -5, 1)" in text and text.count('over "') == 4  # Luminaire, Diffuser,
    # Materials, ReflectorAluminium: nothing else of the stage is written again
    # a bad value names the Blender data, the prim and the property; nothing written
    refusals = report["refusals"]
    assert "(/Luminaire/Materials/DiffuserOpal) lumitrace:transmittance: must be <= 1" \
        in refusals["lumitrace:transmittance"]
    assert "did you mean lumitrace:reflectance" in refusals["lumitrace:diffuseReflectance"]
    assert "must be one of diffuse" in refusals["lumitrace:scattering"]
    assert Path(report["exported"]).read_text() == text
    assert report["asset_line"] == ["asset lumitrace:rayFile = @../rays/led.tm25@"]
    assert report["asset_delta"] == [{"op": "set", "path": "/Luminaire/LED",
                                      "property": "lumitrace:rayFile",
                                      "value": "rays/led.tm25"}]
    assert report["after_reimport"] == 0  # the edited first import is not the stage's now

    # the scene lumitrace reads from the export is the one the deltas give, bit for bit
    delta_stage, edits = _deltas_applied(tmp_path)
    exported = read_stage(report["exported"])
    with_deltas = scene_from_stage(open_with_edits(delta_stage, edits))
    assert exported.content_hash() == with_deltas.content_hash()
    assert exported.content_hash() != read_stage(DEMO).content_hash()
    # the edits-only form composes the same over the original
    edits_only = scene_from_stage(open_with_edits(stage, report["edits_layer"]))
    assert edits_only.content_hash() == with_deltas.content_hash()

    # traced: the same seed gives the same counts, so the same figures
    a, counts_a = _trace(Path(report["exported"]), tmp_path / "a", 7)
    b, counts_b = _trace(delta_stage, tmp_path / "b", 7, "--edits", edits)
    np.testing.assert_array_equal(counts_a, counts_b)
    assert _figures(a) == _figures(b)
    # another seed: flux, LOR and peak agree within their stated errors, while the
    # unedited demo is far from them (the edits were not lost)
    c, _ = _trace(delta_stage, tmp_path / "c", 8, "--edits", edits)
    d, _ = _trace(DEMO, tmp_path / "d", 8)
    for name, (value, error) in _figures(a).items():
        other, other_error = _figures(c)[name]
        assert abs(value - other) <= 4 * math.hypot(error, other_error), name
    lor, lor_error = _figures(a)["lor"]
    original, original_error = _figures(d)["lor"]
    assert original - lor > 10 * math.hypot(lor_error, original_error)


def test_every_kind_of_change_exports_as_the_live_link_sends_it(bpy_python, tmp_path):
    """A flux, a light's size, a mesh edit, a preview-surface colour, another material
    bound, a part turned and moved, a value removed, a part hidden, a part deleted, a new
    part with a new material: the export and the live link's deltas (applied as the
    service applies them) give lumitrace one scene."""
    stage = tmp_path / "downlight.usda"
    shutil.copy(DEMO, stage)
    report = run_bpy("roundtrip.py", "many", stage, tmp_path)
    # the live link's mesh digests are kept until Blender's depsgraph updates the mesh
    assert report["digest_kept_until_update"] and report["digest_after_update"]
    ops = {(op, path) for op, path, _ in report["edits"]}
    assert {("set", "/Luminaire/LED"), ("set", "/Luminaire/Board"),
            ("set", "/Luminaire/Materials/HousingPaint/PreviewSurface"),
            ("bind", "/Luminaire/Housing"), ("transform", "/Luminaire/Diffuser"),
            ("define", "/Luminaire/Baffle"), ("block", "/Luminaire/Materials/ReflectorAluminium"),
            ("visibility", "/Luminaire/Board"), ("active", "/Luminaire/Reflector"),
            ("define", "/Luminaire/Materials/BaffleBlack")} <= ops
    assert not any("Plane" in path for _, path in ops)  # the room is not the luminaire's
    exported = read_stage(report["exported"])
    folder = tmp_path / "deltas"
    folder.mkdir()
    copy = folder / "downlight.usda"
    shutil.copy(DEMO, copy)
    layer = open_edits_layer(folder / "edits.usda")
    apply_deltas(open_with_edits(copy, layer), layer, report["deltas"], folder)
    assert [d["op"] for d in report["deltas"]].count("layer") == 1  # the new prims
    with_deltas = scene_from_stage(open_with_edits(copy, layer))
    assert exported.content_hash() == with_deltas.content_hash()
    original = read_stage(DEMO)
    assert [e.flux for e in exported.emitters] == [1500.0]
    assert exported.emitters[0].width == pytest.approx(25.0)  # mm, the stage's unit
    # the board hidden and the reflector deleted are not traced; the baffle is
    assert set(exported.parts) == set(original.parts) - {"/Luminaire/Board",
                                                         "/Luminaire/Reflector"} \
        | {"/Luminaire/Baffle"}
    assert exported.content_hash() != original.content_hash()
    # the panels show the schema's values and offer the missing ones
    material = report["panels"]["material"]
    assert ["prop", '["lumitrace:specularReflectance"]', "specularReflectance",
            pytest.approx(0.92)] in material
    assert ["label", "reflectance: (schema default)"] in material
    assert ["prop", '["lumitrace:luminousFlux"]', "luminousFlux", 1200.0] in \
        report["panels"]["light"]
    assert ["label", "manufacturer: (schema default)"] in report["panels"]["luminaire"]


def test_one_command_installs_and_enables_the_addon(bpy_python, tmp_path):
    """tools/blender_install.py in a Blender whose user folder is a temporary one: the
    next Blender started with it has the add-on's operators."""
    env = {**os.environ, "BLENDER_USER_RESOURCES": str(tmp_path / "blender")}
    p = subprocess.run([str(bpy_python), str(ROOT / "tools" / "blender_install.py")],
                       capture_output=True, text=True, timeout=120, env=env)
    assert p.returncode == 0 and "installed at" in p.stdout, p.stdout + p.stderr
    assert (tmp_path / "blender" / "scripts" / "addons" / "lumitrace_blender" /
            "__init__.py").exists()
    check = ("import bpy; bpy.ops.wm.read_userpref(); "  # Blender the app reads them itself
             "print('enabled', 'lumitrace_blender' in bpy.context.preferences.addons.keys(),"
             " hasattr(bpy.types, 'LUMITRACE_OT_export_stage'))")
    p = subprocess.run([str(bpy_python), "-c", check], capture_output=True, text=True,
                       timeout=120, env=env)
    assert "enabled True True" in p.stdout, p.stdout + p.stderr


def test_every_stage_survives_the_addons_import_and_export(bpy_python, tmp_path):
    report = run_bpy("roundtrip.py", "stages", tmp_path, *ALL_STAGES)
    assert len(report) == len(ALL_STAGES) >= 9
    for path in ALL_STAGES:
        done = report[str(path)]
        assert done["edits"] == 0 and done["objects"] >= 2, path
        text = Path(done["exported"]).read_text()
        assert 'over "' not in text and 'def "' not in text  # nothing but the sublayer
        assert read_stage(done["exported"]).content_hash() == \
            read_stage(path).content_hash(), path


def test_the_addon_imports_nothing_of_lumitrace_nor_numpy():
    """The add-on runs in Blender's own Python: the standard library, bpy and the USD
    Blender ships only."""
    import ast
    allowed = {"bpy", "bpy_extras", "mathutils", "bmesh", "pxr", "lumitrace_blender"}
    stdlib = set(sys.stdlib_module_names)
    for module in sorted((ROOT / "service" / "lumitrace_blender").glob("*.py")):
        for node in ast.walk(ast.parse(module.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module]
            for name in names:
                top = name.split(".")[0]
                assert top in allowed or top in stdlib, f"{module.name} imports {name}"


def test_the_addons_schema_table_is_lumitraces_schema():
    """Every attribute of lumitrace's API schemas, as USD's schema registry reads
    schemas/, is in the add-on's table with its API, type, fallback, tokens and
    variability (the add-on keeps them as data: Blender's USD knows nothing of them), and
    its ranges are the ones the stage reader validates."""
    import importlib.util

    from pxr import Sdf, Usd

    import lumitrace.schema as ours
    spec = importlib.util.spec_from_file_location(
        "addon_schema", ROOT / "service" / "lumitrace_blender" / "schema.py")
    table = importlib.util.module_from_spec(spec)
    sys.modules["addon_schema"] = table  # (dataclasses look their module up)
    try:
        spec.loader.exec_module(table)  # no bpy needed: the module is data
    finally:
        del sys.modules["addon_schema"]
    registry = Usd.SchemaRegistry()
    seen = set()
    for api in ours.API_SCHEMAS:
        definition = registry.FindAppliedAPIPrimDefinition(api)
        assert definition is not None, api
        for name in definition.GetPropertyNames():
            if name.startswith(table.RESULT_PREFIX):
                assert table.is_result(name)
                continue
            prop = definition.GetAttributeDefinition(name)
            mine = table.BY_NAME.get(name)
            assert mine is not None, f"{name} of {api} is missing from the add-on's table"
            seen.add(name)
            assert mine.api == api, name
            assert mine.usd_type == str(prop.GetTypeName()), name
            assert mine.uniform == (prop.GetVariability() == Sdf.VariabilityUniform), name
            fallback = prop.GetFallbackValue()
            if fallback is None:
                assert mine.fallback is None, name
            elif hasattr(fallback, "__len__") and not isinstance(fallback, str):
                assert tuple(mine.fallback) == pytest.approx(tuple(fallback)), name
            else:
                assert mine.fallback == pytest.approx(fallback), name
            tokens = prop.GetMetadata("allowedTokens")
            assert tuple(mine.tokens) == tuple(tokens or ()), name
    assert seen == set(table.BY_NAME)  # and nothing the schema lacks
    for name, (low, high) in ours.MATERIAL_RANGES.items():
        assert (table.BY_NAME[name].low, table.BY_NAME[name].high) == (low, high), name
    assert table.SCATTERING_TOKENS == tuple(ours.SCATTERING_TOKENS)
    assert table.SYMMETRY_TOKENS == tuple(ours.SYMMETRY_TOKENS)
    assert table.OPENING_SHAPES == tuple(ours.OPENING_SHAPES)
    assert table.PROFILE_KINDS == tuple(ours.PROFILE_KINDS)
    from lumitrace.stage.validate import MAX_LUMINOUS_FLUX
    assert table.MAX_LUMINOUS_FLUX == MAX_LUMINOUS_FLUX
