"""The lumitrace codeless USD schema: registration, fallbacks, generated files."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

import lumitrace  # noqa: F401  (registers the schema before pxr composes anything)
from lumitrace import schema
from pxr import Sdf, Usd
from helpers.paths import ROOT

REPO = ROOT


def test_registry_knows_the_api_schemas():
    assert schema.is_registered()
    registry = Usd.SchemaRegistry()
    for name in schema.API_SCHEMAS:
        assert registry.FindAppliedAPIPrimDefinition(name) is not None, name
        assert Usd.SchemaRegistry.IsAppliedAPISchema(name)
        assert not Usd.SchemaRegistry.IsMultipleApplyAPISchema(name)


_ORDERS = {
    # lumitrace first: the plugin path is set, USD loads only when asked for
    "lumitrace first": "import lumitrace\nloaded = [m for m in sys.modules if m.startswith('pxr')]\n"
                       "assert loaded == [], loaded\nfrom pxr import Usd\n",
    # pxr loaded but no stage composed: the folder is registered at once
    "pxr first": "from pxr import Usd\nimport lumitrace\n",
}


@pytest.mark.parametrize("order", list(_ORDERS))
def test_the_schema_is_known_whichever_loads_first(order):
    """A fresh process that imports lumitrace before composing a stage knows the API
    schemas, whether it loaded pxr before or not; one that did not load pxr has its
    plugin folder first on PXR_PLUGINPATH_NAME (a user's own folders kept after it)."""
    code = ("import os, sys\n" + _ORDERS[order] +
            "from lumitrace.schema import is_registered, PLUGIN_PATH_VARIABLE, SCHEMA_DIR\n"
            "assert is_registered()\n"
            "paths = os.environ.get(PLUGIN_PATH_VARIABLE, '').split(os.pathsep)\n"
            "print(paths.index(str(SCHEMA_DIR)) if str(SCHEMA_DIR) in paths else -1, "
            "paths[-1])\n")
    env = {**os.environ, schema.PLUGIN_PATH_VARIABLE: "/a/folder/of/the/user"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    index, last = out.stdout.split()
    assert last == "/a/folder/of/the/user"
    assert int(index) == (0 if order == "lumitrace first" else -1)


def test_material_api_properties_and_fallbacks():
    definition = Usd.SchemaRegistry().FindAppliedAPIPrimDefinition(schema.MATERIAL_API)
    assert set(definition.GetPropertyNames()) == set(schema.MATERIAL_ATTRIBUTES) | set(
        schema.MATERIAL_COLOUR_ATTRIBUTES)
    for name in schema.MATERIAL_COLOUR_ATTRIBUTES[:3]:
        assert definition.GetSchemaAttributeSpec(name).typeName == Sdf.ValueTypeNames.Float2Array
    assert definition.GetAttributeFallbackValue(schema.ABBE_NUMBER) == 0.0
    for name, fallback in schema.MATERIAL_FALLBACKS.items():
        value = definition.GetAttributeFallbackValue(name)
        if isinstance(fallback, str):
            assert value == fallback
        else:
            assert value == pytest.approx(fallback)
    scattering = definition.GetSchemaAttributeSpec(schema.SCATTERING)
    assert tuple(scattering.allowedTokens) == schema.SCATTERING_TOKENS
    assert scattering.variability == Sdf.VariabilityUniform


def test_emitter_and_luminaire_api_properties():
    registry = Usd.SchemaRegistry()
    emitter = registry.FindAppliedAPIPrimDefinition(schema.EMITTER_API)
    assert emitter.GetPropertyNames() == [schema.BODY, schema.ILLUMINANT, schema.LUMINOUS_FLUX,
                                          schema.RAY_FILE, schema.SPECTRUM]
    assert (emitter.GetSchemaAttributeSpec(schema.SPECTRUM).typeName
            == Sdf.ValueTypeNames.Float2Array)
    assert (emitter.GetSchemaAttributeSpec(schema.LUMINOUS_FLUX).typeName
            == Sdf.ValueTypeNames.Float)
    assert (emitter.GetSchemaAttributeSpec(schema.RAY_FILE).typeName
            == Sdf.ValueTypeNames.Asset)
    luminaire = registry.FindAppliedAPIPrimDefinition(schema.LUMINAIRE_API)
    info = {schema.MANUFACTURER: "string", schema.LUMINAIRE_NAME: "string",
            schema.CATALOGUE_NUMBER: "string", schema.LAMP_DESCRIPTION: "string",
            schema.INPUT_POWER: "double", schema.COLOUR_RENDERING_INDEX: "double",
            schema.SYMMETRY: "token", schema.OPENING_SHAPE: "token",
            schema.OPENING_SIZE: "double3"}
    assert set(luminaire.GetPropertyNames()) == set(schema.RESULT_ATTRIBUTES) | set(info)
    for name, type_name in info.items():
        assert luminaire.GetSchemaAttributeSpec(name).typeName == \
            Sdf.ValueTypeNames.Find(type_name), name
    for name, type_name in schema.RESULT_ATTRIBUTES.items():
        spec = luminaire.GetSchemaAttributeSpec(name)
        assert spec.typeName == Sdf.ValueTypeNames.Find(type_name), name


def test_applied_schemas_on_a_stage(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "applied.usda"))
    material = stage.DefinePrim("/Luminaire/Looks/White", "Material")
    light = stage.DefinePrim("/Luminaire/Led", "DiskLight")
    root = stage.GetPrimAtPath("/Luminaire")
    assert material.CanApplyAPI(schema.MATERIAL_API)
    material.ApplyAPI(schema.MATERIAL_API)
    light.ApplyAPI(schema.EMITTER_API)
    root.ApplyAPI(schema.LUMINAIRE_API)

    assert material.HasAPI(schema.MATERIAL_API)
    assert light.HasAPI(schema.EMITTER_API)
    assert root.HasAPI(schema.LUMINAIRE_API)
    assert not light.HasAPI(schema.MATERIAL_API)

    # Fallbacks come from the schema: nothing is authored on the prims.
    reflectance = material.GetAttribute(schema.REFLECTANCE)
    assert reflectance and not reflectance.HasAuthoredValue()
    assert reflectance.Get() == pytest.approx(0.8)
    assert material.GetAttribute(schema.SCATTERING).Get() == "diffuse"
    assert material.GetAttribute(schema.IOR).Get() == pytest.approx(1.5)
    assert material.GetAttribute(schema.ROUGHNESS).Get() == pytest.approx(0.2)
    flux = light.GetAttribute(schema.LUMINOUS_FLUX)
    assert flux and not flux.HasAuthoredValue() and flux.Get() == 0.0
    assert root.GetAttribute("lumitrace:result:converged").Get() is False

    material.GetAttribute(schema.REFLECTANCE).Set(0.5)
    assert material.GetAttribute(schema.REFLECTANCE).Get() == pytest.approx(0.5)


FRESH_INTERPRETER = textwrap.dedent("""
    import sys
    import lumitrace
    from pxr import Usd
    stage = Usd.Stage.Open(sys.argv[1])
    prim = stage.GetPrimAtPath("/Luminaire/Looks/White")
    assert prim.HasAPI("LumitraceMaterialAPI"), "API not applied"
    assert abs(prim.GetAttribute("lumitrace:reflectance").Get() - 0.8) < 1e-6
    assert prim.GetAttribute("lumitrace:scattering").Get() == "diffuse"
    assert stage.GetPrimAtPath("/Luminaire/Led").GetAttribute(
        "lumitrace:luminousFlux").Get() == 1000.0
    print("ok")
""")


def _fresh_stage(tmp_path):
    path = tmp_path / "fresh.usda"
    path.write_text(textwrap.dedent("""\
        #usda 1.0
        (
            defaultPrim = "Luminaire"
        )
        def Xform "Luminaire"
        {
            def Scope "Looks"
            {
                def Material "White" (
                    prepend apiSchemas = ["LumitraceMaterialAPI"]
                )
                {
                }
            }
            def DiskLight "Led" (
                prepend apiSchemas = ["LumitraceEmitterAPI"]
            )
            {
                float lumitrace:luminousFlux = 1000
            }
        }
        """))
    return path


def test_registration_in_a_fresh_interpreter(tmp_path):
    """A stage file opened right after ``import lumitrace`` in a new process sees the
    schema: registration happens at import, before any stage is composed (and the stage
    waits for the schema registry that import began building on another thread)."""
    result = subprocess.run([sys.executable, "-c", FRESH_INTERPRETER, str(_fresh_stage(tmp_path))],
                            capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "ok"
    assert "registered after" not in result.stderr


FORK_AT_ONCE = """
import os, sys
import lumitrace
pid = os.fork()  # at once: the schema registry's build joined first, not inherited mid-way
if pid:  # the parent checks once its child has (their lines would otherwise interleave)
    _, status = os.waitpid(pid, 0)
    if os.waitstatus_to_exitcode(status):
        sys.exit(os.waitstatus_to_exitcode(status))
""" + FRESH_INTERPRETER.replace("import sys\nimport lumitrace\n", "") + """
if pid == 0:
    sys.stdout.flush()
    os._exit(0)
"""


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="no fork here")
def test_a_process_that_forks_right_after_import_sees_the_schema_on_both_sides(tmp_path):
    result = subprocess.run([sys.executable, "-c", FORK_AT_ONCE, str(_fresh_stage(tmp_path))],
                            capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["ok", "ok"]


def test_a_process_that_ends_right_after_import_exits_cleanly():
    """The registry's build, begun at import, is waited for at exit: no crash in USD's
    teardown, five times over."""
    for _ in range(5):
        result = subprocess.run([sys.executable, "-c", "import lumitrace"],
                                capture_output=True, text=True, timeout=120)
        assert (result.returncode, result.stderr) == (0, "")


def test_generated_plug_info_is_portable():
    text = (REPO / "schemas" / "plugInfo.json").read_text()
    assert "@PLUG_INFO" not in text
    body = "\n".join(line for line in text.splitlines() if not line.startswith("#"))
    plugin = json.loads(body)["Plugins"][0]
    assert plugin["Name"] == "lumitrace"
    assert (plugin["LibraryPath"], plugin["ResourcePath"], plugin["Root"]) == ("", ".", ".")
    assert set(plugin["Info"]["Types"]) == set(schema.API_SCHEMAS)


def test_generated_files_are_up_to_date():
    pytest.importorskip("jinja2")
    result = subprocess.run([sys.executable, str(REPO / "tools" / "generate_schema.py"),
                             "--check"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
