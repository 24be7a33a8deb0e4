"""The result layer as ``.usda`` text, written and its ``customLayerData`` read back,
without loading USD: a run of a kept scene (:mod:`lumitrace.stage.scene_cache`) publishes
without USD's 0.17 CPU seconds of loading.

The text is what USD's own authoring API makes of the same values (tested against it
through USD's parser): the luminaire's ``over`` with ``LumitraceLuminaireAPI`` and its
``lumitrace:result:*`` attributes, and the ``lumitraceRepresentation`` variant set whose
``photometric`` variant holds the IES-shaped stand-in light and deactivates the emitters.
"""
from __future__ import annotations

import math
import re
import struct
from pathlib import Path
from typing import Mapping

from ..schema import EMITTER_API, LUMINAIRE_API, LUMINOUS_FLUX, RESULT_KINDS, RESULT_PREFIX
from ..stage.usda_scan import matching_bracket, skip_token

#: Variant set on the luminaire: "geometry" (its own emitters, the default) or
#: "photometric" (one UsdLux light shaped by the computed IES file, emitters off).
REPRESENTATION = "lumitraceRepresentation"
PHOTOMETRIC_LIGHT = "lumitracePhotometricLight"
_INDENT = "    "
_FLOAT32 = struct.Struct("<f")


def result_layer_text(prim_path: str, values: Mapping, light: Mapping | None,
                      layer_data: Mapping[str, str] | None, units: tuple[str, float] | None,
                      documentation: str) -> str:
    """The result layer over the prim ``prim_path``: ``values`` by result attribute
    (checked and converted: an asset's value is its path as written), ``light`` the
    stand-in light (see :func:`photometric_variant`), ``layer_data`` the layer's
    ``lumitrace:*`` custom data, ``units`` the stage's (up axis, metres per unit)."""
    names = prim_path.strip("/").split("/")
    header = [f"customLayerData = {{"] + \
        [f"{_INDENT}string {_string(f'lumitrace:{k}')} = {_string(str(v))}"
         for k, v in (layer_data or {}).items()] + ["}"] if layer_data else []
    if len(names) == 1:
        header.append(f"defaultPrim = {_string(names[0])}")
    header.append(f"doc = {_string(documentation)}")
    if units is not None:
        header += [f"metersPerUnit = {_double(float(units[1]))}",
                   f"upAxis = {_string(str(units[0]))}"]
    metadata = [f'prepend apiSchemas = [{_string(LUMINAIRE_API)}]']
    if light is not None:
        metadata += [f"variants = {{", f"{_INDENT}string {REPRESENTATION} = \"geometry\"",
                     "}", f"prepend variantSets = {_string(REPRESENTATION)}"]
    body = [f"{RESULT_KINDS[key]} {RESULT_PREFIX}{key} = {_value(RESULT_KINDS[key], v)}"
            for key, v in values.items()]
    if light is not None:
        body += photometric_variant(light, prim_path)
    prim = _prim("over", names[-1], metadata, body)
    for name in reversed(names[:-1]):
        prim = _prim("over", name, [], prim)
    lines = ["#usda 1.0", "(", *_indented(header), ")", "", *prim]
    return "\n".join(lines) + "\n\n"


def photometric_variant(light: Mapping, prim_path: str) -> list[str]:
    """The ``lumitraceRepresentation`` variant set's lines: ``geometry`` empty;
    ``photometric`` a DiskLight the size of the luminous opening at its centre, emitting
    down (local -Z to nadir, +X to C0), shaped by the IES file, with the luminaire's flux,
    and the traced emitters deactivated.

    ``light`` holds ``ies`` (asset path relative to the layer), ``flux`` (lm), ``radius``
    and ``position`` (stage units, luminaire space), ``up_axis`` and ``emitters`` (paths
    under ``prim_path``)."""
    flux = float(light["flux"])
    ops = ['"xformOp:translate"']
    attrs = [f"float inputs:intensity = {_float(flux / math.pi)}",  # normalised: pi * L
             "bool inputs:normalize = 1",
             f"float inputs:radius = {_float(float(light['radius']))}",
             f"asset inputs:shaping:ies:file = {_asset(str(light['ies']))}",
             "bool inputs:shaping:ies:normalize = 1",
             f"float {LUMINOUS_FLUX} = {_float(flux)}"]
    if light.get("up_axis", "Z") == "Y":
        attrs.append("float xformOp:rotateX = -90")  # local -Z to -Y, local +X stays C0
        ops.append('"xformOp:rotateX"')
    x, y, z = (_double(float(v)) for v in light["position"])
    attrs += [f"double3 xformOp:translate = ({x}, {y}, {z})",
              f"uniform token[] xformOpOrder = [{', '.join(ops)}]"]
    photometric = _prim("def DiskLight", PHOTOMETRIC_LIGHT,
                        [f"prepend apiSchemas = [{_string(EMITTER_API)}, \"ShapingAPI\"]"],
                        attrs)
    for tree in _emitter_tree(light.get("emitters", ()), prim_path):
        photometric += tree
    return [f"variantSet {_string(REPRESENTATION)} = {{",
            *_indented(['"geometry" {', "", "}",
                        '"photometric" {', *_indented(photometric), "", "}"]), "}"]


def _emitter_tree(paths, prim_path: str) -> list[list[str]]:
    """The ``over`` specs that deactivate ``paths`` (prims under ``prim_path``), nested
    as their paths are, one tree per child of the luminaire."""
    root: dict = {}
    prefix = prim_path.rstrip("/") + "/"
    for path in paths:
        path = str(path)
        if path == prim_path:  # the luminaire is the light: the stand-in replaces nothing
            continue
        if not path.startswith(prefix):
            raise ValueError(f"emitter {path} is not under the luminaire {prim_path}")
        node = root
        for name in path[len(prefix):].split("/"):
            node = node.setdefault(name, {})
        node[None] = True

    def lines(name: str, node: dict) -> list[str]:
        children = [lines(n, c) for n, c in node.items() if n is not None]
        metadata = ["active = false"] if node.get(None) else []
        return _prim("over", name, metadata, [line for c in children for line in c])

    return [lines(n, c) for n, c in root.items() if n is not None]


def _prim(specifier: str, name: str, metadata: list[str], body: list[str]) -> list[str]:
    head = f"{specifier} {_string(name)}"
    out = [head + " (", *_indented(metadata), ")"] if metadata else [head]
    return out + ["{", *_indented(body), "}"]


def _indented(lines: list[str]) -> list[str]:
    return [_INDENT + line if line else line for line in lines]


def _value(kind: str, value) -> str:
    if kind == "asset":
        return _asset(str(value))
    if kind == "double":
        return _double(float(value))
    if kind == "bool":
        return "1" if value else "0"
    if kind in ("int", "int64"):
        return str(int(value))
    return _string(str(value))


def _double(value: float) -> str:
    """A double as USD reads it back to the same bits (shortest round trip)."""
    if math.isnan(value):
        return "nan"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    text = repr(value)
    return text[:-2] if text.endswith(".0") else text


def _float(value: float) -> str:
    """A single-precision value (rounded to nearest, as USD rounds a double set on a
    float), in the fewest digits that read back to it."""
    single = _FLOAT32.unpack(_FLOAT32.pack(value))[0]
    if not math.isfinite(single):
        return _double(single)
    for digits in range(1, 10):
        text = f"{single:.{digits}g}"
        if _FLOAT32.unpack(_FLOAT32.pack(float(text)))[0] == single:
            return _double(float(text))
    return _double(single)


_ESCAPES = {"\\": "\\\\", '"': '\\"', "\n": "\\n", "\r": "\\r", "\t": "\\t"}


def _string(text: str) -> str:
    """A double-quoted usda string: backslash, quote and control characters escaped."""
    out = []
    for c in text:
        if c in _ESCAPES:
            out.append(_ESCAPES[c])
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            out.append(f"\\x{ord(c):02x}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'


def _asset(path: str) -> str:
    """An asset path: ``@path@``, or ``@@@path@@@`` where it holds an ``@``."""
    if "\n" in path or "\r" in path:
        raise ValueError(f"an asset path cannot hold a line break: {path!r}")
    if "@" not in path:
        return f"@{path}@"
    return "@@@" + path.replace("@@@", "\\@@@") + "@@@"


# --------------------------------------------------------------------------------------
# Reading the layer's custom data back
# --------------------------------------------------------------------------------------

_ENTRY = re.compile(r'\s*string\s+(?=["\'])')
_HEADER = re.compile(r"#usda 1\.0[ \t]*\r?\n\s*\(")  # the one version read here
_OCTAL = re.compile(r"[0-7]{1,3}")
_HEX = re.compile(r"[0-9a-fA-F]{1,2}")
_UNESCAPE = {"n": "\n", "t": "\t", "r": "\r", "a": "\a", "b": "\b", "f": "\f", "v": "\v",
             "\\": "\\", "'": "'", '"': '"', "?": "?"}


def custom_layer_data(layer: Path) -> dict[str, str] | None:
    """The string entries of the ``customLayerData`` of the ``.usda`` file ``layer``, read
    from its header without USD; {} where it has none; None where its header is not
    plain enough to be sure of (another type of entry, an unknown form): then ask USD."""
    try:
        with open(layer, "rb") as f:
            head = f.read(1 << 20)
        text = head.decode("utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    match = _HEADER.match(text)
    if match is None:
        return None
    try:
        header = text[match.end():matching_bracket(text, match.end() - 1)]
        at = _statement(header, "customLayerData")
        if at is None:
            return {}
        if _statement(header, "customLayerData", at + 1) is not None:
            return None  # said twice: which one counts is USD's to say
        i = header.index("{", at)
        return _entries(header[i + 1:matching_bracket(header, i)])
    except ValueError:
        return None


def _statement(header: str, name: str, start: int = 0) -> int | None:
    """Where the header's first statement ``name = `` from ``start`` begins (outside
    strings and brackets)."""
    i = start
    while i < len(header):
        j = skip_token(header, i)
        if j != i:
            i = j
        elif header[i] in "([{":
            i = matching_bracket(header, i) + 1
        elif header.startswith(name, i) and \
                (i == 0 or not (header[i - 1].isalnum() or header[i - 1] == "_")) and \
                re.match(r"\s*=", header[i + len(name):]):
            return i
        else:
            i += 1
    return None


def _entries(body: str) -> dict[str, str] | None:
    """``string "key" = "value"`` entries, one a line; None for any other form."""
    out: dict[str, str] = {}
    i = 0
    while True:
        i = _skip_blank(body, i)
        if i >= len(body):
            return out
        m = _ENTRY.match(body, i)
        if m is None:
            return None
        i = m.end()
        key, i = _string_at(body, i)
        eq = _skip_blank(body, i)
        if not body.startswith("=", eq):
            return None
        value, i = _string_at(body, _skip_blank(body, eq + 1))
        out[key] = value


def _skip_blank(text: str, i: int) -> int:
    while i < len(text):
        if text[i].isspace():
            i += 1
        elif text[i] == "#":
            i = skip_token(text, i)
        else:
            break
    return i


def _string_at(text: str, i: int) -> tuple[str, int]:
    """The usda string literal at ``i`` (unescaped) and the index after it."""
    if i >= len(text) or text[i] not in "\"'":
        raise ValueError("a string expected")
    end = skip_token(text, i)
    q = 3 if text[i:i + 3] in ('"""', "'''") else 1
    raw = text[i + q:end - q]
    out, k = [], 0
    while k < len(raw):
        c = raw[k]
        if c != "\\" or k + 1 == len(raw):
            out.append(c)
            k += 1
            continue
        e = raw[k + 1]
        if e in _UNESCAPE:
            out.append(_UNESCAPE[e])
            k += 2
        elif e == "x" and _HEX.match(raw, k + 2):
            digits = _HEX.match(raw, k + 2).group()
            out.append(_byte(int(digits, 16)))
            k += 2 + len(digits)
        elif _OCTAL.match(raw, k + 1):
            digits = _OCTAL.match(raw, k + 1).group()
            out.append(_byte(int(digits, 8)))
            k += 1 + len(digits)
        else:
            raise ValueError("an escape USD may read otherwise")
    return "".join(out), end


def _byte(code: int) -> str:
    """An escaped byte: ASCII only (a byte past it is part of a UTF-8 sequence USD would
    decode with its neighbours)."""
    if code >= 0x80:
        raise ValueError("an escaped byte past ASCII")
    return chr(code)
