"""The reference pages, generated while the site builds (the ``gen-files`` plugin runs this
file): the USD schema from ``schemas/schema.usda``, the scene-delta protocol from
``schemas/scene-delta.schema.json``, the command line from its own parser and the result
record from :data:`lumitrace.schema.RESULT_FIELDS`. Nothing here is written by hand twice:
an attribute, an option or a delta field added to its source appears on its page.

Each page is a plain function returning Markdown, so the tests can read them without the
documentation tools installed.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "service") not in sys.path:  # a checkout without an install
    sys.path.insert(0, str(ROOT / "service"))

SCHEMA_USDA = ROOT / "schemas" / "schema.usda"
DELTA_SCHEMA = ROOT / "schemas" / "scene-delta.schema.json"


def _cell(text: object) -> str:
    """``text`` made safe for one Markdown table cell (one line, no bare pipes)."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _table(head: list[str], rows: list[list[object]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------------
# The USD schema
# ------------------------------------------------------------------------------------------

def _input_limits() -> dict[str, tuple[str, str]]:
    """Unit and allowed values of each attribute a user authors, as the stage reader checks
    them (the numbers are the reader's own constants). A result attribute takes its unit
    from the result record instead."""
    from lumitrace import schema as s
    from lumitrace.stage.colour import SPECTRUM_RANGES
    from lumitrace.stage.profile import SEGMENTS_RANGE as PROFILE_SEGMENTS
    from lumitrace.stage.validate import MAX_LUMINOUS_FLUX

    def closed(name):
        low, high = s.MATERIAL_RANGES[name]
        return f"[{low:g}, {high:g}]"

    def pairs(name):
        low, high = SPECTRUM_RANGES[name]
        values = f">= {low:g}" if math.isinf(high) else f"in [{low:g}, {high:g}]"
        return f"at least two (nm, value) pairs, wavelengths increasing, values {values}"

    text = ("one line of at most 1000 characters: no control characters or line breaks "
            "(see files-and-safety)")
    return {
        s.SCATTERING: ("", "one of " + ", ".join(s.SCATTERING_TOKENS)),
        s.REFLECTANCE: ("fraction", closed(s.REFLECTANCE) + "; with transmittance at most 1"),
        s.SPECULAR_REFLECTANCE: ("fraction", closed(s.SPECULAR_REFLECTANCE)),
        s.TRANSMITTANCE: ("fraction", closed(s.TRANSMITTANCE) + "; with reflectance at most 1"),
        s.IOR: ("", f"finite, > {s.IOR_EXCLUSIVE_MIN:g}"),
        s.ROUGHNESS: ("", closed(s.ROUGHNESS)),
        s.REFLECTANCE_SPECTRUM: ("nm, fraction", pairs(s.REFLECTANCE_SPECTRUM)),
        s.SPECULAR_SPECTRUM: ("nm, fraction", pairs(s.SPECULAR_SPECTRUM)),
        s.TRANSMITTANCE_SPECTRUM: ("nm, fraction", pairs(s.TRANSMITTANCE_SPECTRUM)),
        s.ABBE_NUMBER: ("", "0 (no dispersion) or >= 1"),
        s.SELLMEIER: ("B: 1, C: um^2", "six finite numbers, C >= 0, an index >= 1 over "
                                       "380-780 nm"),
        s.LUMINOUS_FLUX: ("lm", f"finite, > 0, at most {MAX_LUMINOUS_FLUX:g}; unauthored: "
                                "from the UsdLux inputs"),
        s.SPECTRUM: ("nm, relative power", pairs(s.SPECTRUM) + ", some power in 380-780 nm"),
        s.ILLUMINANT: ("", '"blackbody K", "daylight K" or a colour-science illuminant or '
                           "light source name"),
        s.BODY: ("", "true or false"),
        s.RAY_FILE: ("", "an IES TM-25-13 ray file, resolved like any asset path"),
        s.MANUFACTURER: ("", text),
        s.LUMINAIRE_NAME: ("", text),
        s.CATALOGUE_NUMBER: ("", text),
        s.LAMP_DESCRIPTION: ("", text),
        s.AUTHOR: ("", text),
        s.BUG_FORWARD: ("", "one of " + ", ".join(s.BUG_FORWARD_TOKENS) + " (see "
                            "deliverables)"),
        s.INPUT_POWER: ("W", "finite, >= 0"),
        s.COLOUR_RENDERING_INDEX: ("Ra", "finite, from 0 to 100"),
        s.PROFILE_POINTS: ("the mesh's units", "at least two finite (r, z) pairs, no two in "
                                               "a row the same, r >= 0 in a revolve"),
        s.PROFILE_KIND: ("", "one of " + ", ".join(s.PROFILE_KINDS)),
        s.PROFILE_SEGMENTS: ("", "; ".join(f"{lo} to {hi} for {kind}" for kind, (lo, hi)
                                           in PROFILE_SEGMENTS.items())),
        s.PROFILE_LENGTH: ("the mesh's units", "finite, > 0 (an extrusion's)"),
        s.SYMMETRY: ("", "one of " + ", ".join(s.SYMMETRY_TOKENS) + " (see "
                         "files-you-ship)"),
        s.OPENING_SHAPE: ("", "one of " + ", ".join(s.OPENING_SHAPES)),
        s.OPENING_SIZE: ("stage units", "length and width > 0, height >= 0, finite; a round "
                                        "opening's length and width equal"),
    }


def _result_units() -> dict[str, str]:
    from lumitrace import schema as s

    return {s.RESULT_PREFIX + f.attribute: f.unit for f in s.RESULT_FIELDS if f.attribute}


def _usd_value(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def schema_attributes() -> list[dict]:
    """Every attribute of the lumitrace API schemas, in ``schema.usda``'s order: its
    schema, name, type, unit, allowed values, fallback and documentation."""
    from pxr import Sdf

    limits, units = _input_limits(), _result_units()
    layer = Sdf.Layer.FindOrOpen(str(SCHEMA_USDA))
    out = []
    for prim in layer.rootPrims:
        if prim.name == "GLOBAL":
            continue
        for prop in prim.properties:
            name = prop.name
            if name in limits:
                unit, allowed = limits[name]
            elif name in units:
                unit, allowed = units[name], "written by lumitrace"
            else:
                raise LookupError(
                    f"{name} (schemas/schema.usda) has no unit and range in "
                    "docs/gen_reference.py: add it to _input_limits (an input) or to "
                    "lumitrace.schema.RESULT_FIELDS (a result)")
            kind = str(prop.typeName)
            if prop.variability == Sdf.VariabilityUniform:
                kind = "uniform " + kind
            tokens = prop.GetInfo("allowedTokens") if prop.HasInfo("allowedTokens") else None
            if tokens:
                allowed = "one of " + ", ".join(tokens)
            default = prop.default if prop.HasDefaultValue() else None
            out.append({"schema": prim.name, "name": name, "type": kind, "unit": unit,
                        "range": allowed, "default": _usd_value(default),
                        "doc": prop.documentation, "schema_doc": prim.documentation})
    return out


_APPLIES_TO = {
    "LumitraceMaterialAPI": "a UsdShade Material (bound as usual) or a gprim",
    "LumitraceEmitterAPI": "a UsdLux light (Sphere, Disk, Rect or Cylinder light)",
    "LumitraceLuminaireAPI": "the luminaire prim (the stage's default prim)",
}


def schema_page() -> str:
    attrs = schema_attributes()
    out = ["# USD schema reference\n",
           "Generated from `schemas/schema.usda` as the site builds; units and allowed "
           "values are what the stage reader checks (USD itself enforces neither). A value "
           "outside them stops a trace with one error naming the prim and the property. "
           "The guide to using them is [Modelling a luminaire](../guide/modelling.md).\n",
           "To see the schema in a DCC or usdview, put its folder on USD's plugin path: "
           "`export PXR_PLUGINPATH_NAME=$PWD/schemas`.\n"]
    for schema in dict.fromkeys(a["schema"] for a in attrs):
        rows = [a for a in attrs if a["schema"] == schema]
        out.append(f"## {schema}\n")
        out.append(f"Applied to {_APPLIES_TO.get(schema, 'a prim')}. "
                   f"{_cell(rows[0]['schema_doc'].split(chr(10) + chr(10))[0])}\n")
        for a in rows:  # a definition list: the meaning is too long for a table's cell
            facts = [f"`{a['type']}`", f"unit: {a['unit']}" if a["unit"] else "no unit",
                     f"allowed: {_cell(a['range'])}",
                     f"fallback: `{a['default']}`" if a["default"] else "no fallback"]
            out.append(f"`{a['name']}`\n: {' · '.join(facts)}\n\n  {_cell(a['doc'])}\n")
    return "\n".join(out)


# ------------------------------------------------------------------------------------------
# The scene-delta protocol
# ------------------------------------------------------------------------------------------

def _describe(spec: dict, defs: dict) -> str:
    """A JSON Schema fragment in words: its type and constraints."""
    if "$ref" in spec:
        name = spec["$ref"].rsplit("/", 1)[1]
        words = {"primPath": "prim path", "propertyName": "property name",
                 "vec3": "3 numbers", "value": "JSON value"}.get(name, name)
        ref = defs[name]
        extra = [f"at most {ref['maxLength']} characters"] if "maxLength" in ref else []
        return words + (f" ({', '.join(extra)})" if extra else "")
    if "const" in spec:
        return f'`"{spec["const"]}"`'
    if "enum" in spec:
        return "one of " + ", ".join(f"`{v}`" for v in spec["enum"])
    kind = spec.get("type", "")
    if kind == "array":
        items = _describe(spec.get("items", {}), defs)
        lo, hi = spec.get("minItems"), spec.get("maxItems")
        count = f"{lo}" if lo == hi and lo is not None else \
            f"{lo or 0} to {hi:,}" if hi else f"at least {lo}" if lo else "any number of"
        if spec.get("items", {}).get("type") == "array":
            return f"{count} arrays of {items}"
        head, sep, rest = items.partition(", ") if items.startswith("string") else \
            items.partition(" (")
        many = head if head.endswith("s") else head + "s"
        return f"{count} {many}" + (f"{sep}{rest}" if rest else "")
    if kind == "object":
        if "additionalProperties" in spec and isinstance(spec["additionalProperties"], dict):
            value = _describe(spec["additionalProperties"], defs)
            most = spec.get("maxProperties")
            return f"object of property name -> {value}" + \
                (f" (at most {most})" if most else "")
        return "object"
    words = [kind if isinstance(kind, str) else " or ".join(kind)]
    if "minimum" in spec:
        words.append(f">= {spec['minimum']}")
    if "maxLength" in spec:
        words.append(f"at most {spec['maxLength']} characters")
    if "pattern" in spec:
        words.append(f"matching `{spec['pattern']}`")
    return ", ".join(words)


def protocol_page() -> str:
    schema = json.loads(DELTA_SCHEMA.read_text())
    defs = schema["$defs"]
    out = ["# Scene-delta protocol reference\n",
           f"Generated from `schemas/scene-delta.schema.json` ({schema['$schema']}) as the "
           "site builds; the service serves the same file at `GET /schema`. How the "
           "service applies deltas, and examples, are in "
           "[The live service](../guide/service.md).\n",
           f"{schema['description']}\n", "## The batch\n",
           "The body of `POST /deltas`:\n",
           _table(["field", "required", "type", "meaning"],
                  [[f"`{name}`", "yes" if name in schema["required"] else "no",
                    _describe(spec, defs), spec.get("description", "")]
                   for name, spec in schema["properties"].items()]),
           "Each delta is an object whose `op` is one of: " +
           ", ".join(f"[`{op}`](#{op})" for op in
                     defs["delta"]["properties"]["op"]["enum"]) + ".\n"]
    for op in defs["delta"]["properties"]["op"]["enum"]:
        spec = defs[op]
        out.append(f"## `{op}`\n")
        if spec.get("description"):
            out.append(spec["description"] + "\n")
        out.append(_table(["field", "required", "type"],
                          [[f"`{name}`", "yes" if name in spec.get("required", []) else "no",
                            _describe(field, defs)]
                           for name, field in spec["properties"].items()]))
        if op == "transform":
            out.append("Give either `matrix` or any of `translate`, `rotate` and `scale`, "
                       "not both.\n")
    out.append("## Shared definitions\n")
    out.append(_table(["name", "type", "meaning"],
                      [[f"`{name}`", _describe({k: v for k, v in spec.items()
                                                 if k != "description"}, defs)
                        if "anyOf" not in spec else "number, boolean, string, or array of "
                                                    f"at most {spec['anyOf'][1]['maxItems']:,}"
                                                    " values (nested)",
                        spec.get("description", "")]
                       for name, spec in defs.items()
                       if name in ("primPath", "propertyName", "vec3", "value")]))
    return "\n".join(out)


# ------------------------------------------------------------------------------------------
# The command line
# ------------------------------------------------------------------------------------------

def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _option_row(action: argparse.Action) -> list[str] | None:
    if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
        return None
    if action.option_strings:
        metavar = "" if action.nargs == 0 else \
            " " + (action.metavar or action.dest.upper() if not action.choices
                   else "{" + ",".join(map(str, action.choices)) + "}")
        name = ", ".join(f"`{o}{metavar}`" for o in action.option_strings)
    else:
        name = f"`{action.metavar or action.dest.upper()}`"
        if action.choices:
            name += " (" + ", ".join(f"`{c}`" for c in action.choices) + ")"
    text = (action.help or "") % {"default": action.default} if action.help else ""
    return [name, text]


def cli_parser() -> argparse.ArgumentParser:
    from lumitrace.cli import build_parser

    return build_parser()


def cli_commands() -> dict[str, argparse.ArgumentParser]:
    return _subcommands(cli_parser())


def _help_of(parser: argparse.ArgumentParser, name: str) -> str:
    top = cli_parser()
    for action in top._actions:
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                if choice.dest == name:
                    return choice.help or ""
    return ""


def cli_page() -> str:
    out = ["# Command line reference\n",
           "Generated from the `lumitrace` command's own parser as the site builds: "
           "`lumitrace COMMAND --help` prints the same. Every command exits 0 when done and "
           "2 on bad input (one line naming what is wrong); the exit statuses particular "
           "to a command are in its description and in "
           "[Tracing and convergence](../guide/tracing.md#exit-statuses).\n"]
    commands = cli_commands()
    out.append(_table(["command", "what it does"],
                      [[f"[`{name}`](#lumitrace-{name})", _help_of(p, name)]
                       for name, p in commands.items()]))
    for name, parser in commands.items():
        usage = parser.format_usage().replace("usage: ", "").strip()
        out.append(f"## `lumitrace {name}`\n")
        if parser.description:
            out.append(parser.description + "\n")
        out.append("```text\n" + usage + "\n```\n")
        rows = [r for r in map(_option_row, parser._actions) if r]
        if rows:
            out.append(_table(["argument", "meaning"], rows))
    return "\n".join(out)


# ------------------------------------------------------------------------------------------
# The result record
# ------------------------------------------------------------------------------------------

def record_page() -> str:
    from lumitrace.schema import RESULT_FIELDS, RESULT_PREFIX

    out = ["# Result record reference\n",
           "Every figure of a traced result is declared once, in "
           "`lumitrace.schema.RESULT_FIELDS`, and written from there to each place that "
           "holds it: the `--json` summary of `lumitrace trace` (nested under `outputs`, "
           "`photometry` or `colour` where a group is given), the service's `GET /results`, "
           "the `lumitrace:result:*` attributes of the result layer and the JSON metadata "
           "of the EXR header. This page is generated from that declaration as the site "
           "builds. The files themselves are described in "
           "[The outputs](../guide/outputs.md).\n",
           ]
    for f in RESULT_FIELDS:  # a definition list: the meaning is too long for a table's cell
        facts = [f.kind, f"unit: {f.unit}" if f.unit else "no unit",
                 f"in `{f.group}`" if f.group else "at the top level",
                 f"layer: `{RESULT_PREFIX}{f.attribute}`" if f.attribute else "not in the layer",
                 f"EXR: `{f.exr}`" if f.exr else "not in the EXR"]
        out.append(f"`{f.key}`\n: {' · '.join(facts)}\n\n  {_cell(f.doc)}\n")
    return "\n".join(out)


PAGES = {
    "reference/schema.md": schema_page,
    "reference/protocol.md": protocol_page,
    "reference/cli.md": cli_page,
    "reference/record.md": record_page,
}


def main() -> None:
    import mkdocs_gen_files

    for path, make in PAGES.items():
        with mkdocs_gen_files.open(path, "w") as f:
            f.write(make())


if __name__ in ("__main__", "<run_path>"):
    main()
