"""Folding the edits layer into a ``.usda`` root layer as a text edit: only the statements
the edits change are rewritten (each property the edits hold, each prim they add), so the
file's comments, formatting and prim order stay as they were.

The text of every rewritten statement is taken from the merge Sdf makes of the same two
layers (:func:`merge_text` is given it), and the edited text must read back as that very
layer; where it does not, or the edits hold what a statement edit cannot carry (prim
metadata such as ``active`` or API schemas, variant sets, a removed prim), the caller
falls back to writing the Sdf merge.
"""
from __future__ import annotations

from dataclasses import dataclass

from pxr import Sdf
from ..stage.usda_scan import layer_of_text, matching_bracket, skip_token

#: Words that open a nested block statement (a prim, or a variant set) in a prim's body.
_BLOCKS = ("def", "over", "class", "variantSet")
#: Suffixes of a property statement that are still the same property.
_SUFFIXES = (".connect", ".timeSamples", ".spline", ".default")


@dataclass(frozen=True)
class Statement:
    """One statement of a block's body: ``start`` (its line's start) to ``end`` (after
    its last line), ``kind`` (``prim``, ``variantSet`` or ``property``), ``name`` and,
    for a prim, where its body's text runs (``body``: after ``{`` to ``}``)."""

    start: int
    end: int
    kind: str
    name: str
    body: tuple[int, int] | None = None


def statements(text: str, start: int, end: int) -> list[Statement]:
    """The statements of the body ``text[start:end]`` (a prim's, or the layer's after its
    metadata), comments and blank lines left between them."""
    out, i = [], start
    while i < end:
        if text[i] in " \t\r\n;":
            i += 1
            continue
        if text[i] == "#":
            i = skip_token(text, i)
            continue
        line_start = text.rfind("\n", 0, i) + 1
        word = text[i:i + 12].split(None, 1)[0] if text[i:i + 12].split() else ""
        if word in _BLOCKS:
            out.append(_block(text, i, line_start, word))
        else:
            out.append(_property(text, i, line_start, end))
        i = out[-1].end
    return out


def _block(text: str, i: int, line_start: int, word: str) -> Statement:
    """A prim or variant set statement from its first word at ``i``."""
    j = i
    while text[j] != "{":
        k = skip_token(text, j)
        if k != j:
            j = k
        elif text[j] == "(":
            j = matching_bracket(text, j) + 1
        else:
            j += 1
    close = matching_bracket(text, j)
    head = text[i:j]
    quoted = head.split('"')
    name = quoted[1] if len(quoted) > 2 else ""
    end = text.find("\n", close)
    kind = "prim" if word != "variantSet" else "variantSet"
    return Statement(line_start, len(text) if end < 0 else end + 1, kind, name,
                     (j + 1, close))


def _property(text: str, i: int, line_start: int, limit: int) -> Statement:
    """A property (or other one-line-at-depth-0) statement from ``i`` to its line's end."""
    j, first = i, None
    while j < limit and text[j] != "\n":
        k = skip_token(text, j)
        if k != j:
            j = k
            continue
        if text[j] in "([{":
            if first is None and text[j] == "(":
                first = j
            j = matching_bracket(text, j) + 1
            continue
        if text[j] == "=" and first is None:
            first = j
        j += 1
    head = text[i:first if first is not None else j].split()
    name = head[-1] if head else ""
    for suffix in _SUFFIXES:
        name = name.removesuffix(suffix)
    return Statement(line_start, min(j + 1, len(text)), "property", name)


def _trailing_comment(text: str, statement: Statement) -> str | None:
    """The comment ending a one-line statement (``# ...``), if it has one."""
    line_end = text.find("\n", statement.start)
    line_end = len(text) if line_end < 0 else line_end
    if line_end + 1 < statement.end:
        return None
    i = statement.start
    while i < line_end:
        if text[i] == "#":
            return text[i:line_end].rstrip("\r")
        j = skip_token(text, i)
        i = j if j != i else i + 1
    return None


def _layer_body(text: str) -> tuple[int, int]:
    """Where the root-level statements run: after the header line and metadata block."""
    i = text.find("\n") + 1
    while i < len(text) and (text[i] in " \t\r\n" or text[i] == "#"):
        i = skip_token(text, i) if text[i] == "#" else i + 1
    if i < len(text) and text[i] == "(":
        i = matching_bracket(text, i) + 1
    return i, len(text)


def _find_prim(text: str, path: Sdf.Path) -> tuple[int, int] | None:
    """The body (start, end) of the prim at ``path`` (the layer's for the pseudo-root);
    None where it has no block in ``text`` or more than one."""
    body = _layer_body(text)
    for name in path.pathString.strip("/").split("/") if path.pathString != "/" else []:
        found = [s for s in statements(text, *body) if s.kind == "prim" and s.name == name]
        if len(found) != 1:
            return None
        body = found[0].body
    return body


def _indent(text: str, body: tuple[int, int], depth: int) -> str:
    """The indentation of the statements in a body (its first one's, or 4 per level)."""
    found = statements(text, *body)
    if found:
        line = text[found[0].start:text.find("\n", found[0].start)]
        return line[:len(line) - len(line.lstrip())]
    return "    " * depth


def _reindent(chunk: str, have: str, want: str) -> str:
    """``chunk``'s lines with their leading ``have`` replaced by ``want``."""
    return "".join(want + line[len(have):] if line.startswith(have) else line
                   for line in chunk.splitlines(keepends=True))


def _statement_text(source: str, path: Sdf.Path) -> tuple[str, str]:
    """The text of the statements of property or prim ``path`` in ``source`` (an Sdf
    export) and their indentation there."""
    parent = path.GetPrimPath() if path.IsPropertyPath() else path.GetParentPath()
    body = _find_prim(source, parent)
    name = path.name
    kind = "property" if path.IsPropertyPath() else "prim"
    chunk = "".join(source[s.start:s.end] for s in statements(source, *body)
                    if s.kind == kind and s.name == name)
    return chunk, "    " * parent.pathElementCount


def _edits_supported(edits: Sdf.Layer) -> list[Sdf.Path] | None:
    """The paths (properties of prims, and prims the edits add) a statement edit must
    rewrite; None when the edits hold prim metadata or anything else it cannot carry."""
    changed: list[Sdf.Path] = []
    if edits.rootPrimOrder or edits.subLayerPaths:
        return None

    def walk(spec: Sdf.PrimSpec) -> bool:
        for child in spec.nameChildren:
            if child.specifier != Sdf.SpecifierOver:  # a prim the edits define
                changed.append(child.path)
                continue
            meta = set(child.ListInfoKeys()) - {"specifier"}
            if meta or child.variantSets or child.nameChildrenOrder:
                return False
            changed.extend(p.path for p in child.properties)
            if not walk(child):
                return False
        return True
    return changed if walk(edits.pseudoRoot) else None


def merge_text(text: str, edits: Sdf.Layer, merged: Sdf.Layer) -> tuple[str | None, str]:
    """``text`` (a ``.usda`` root layer) with the statements ``edits`` change replaced by
    their text in ``merged`` (the Sdf merge of the two), and ""; or None and why, when
    that is not certain to read back as ``merged`` (see the module docstring)."""
    paths = _edits_supported(edits)
    if paths is None:
        return None, "the edits hold prim metadata, variants or an order of prims"
    source = merged.ExportToString()
    try:
        for path in paths:
            text = _replace(text, source, path)
            if text is None:
                return None, f"the file has no single block for the prim of {path}"
    except ValueError as e:
        return None, f"the file's text could not be followed ({e})"
    differs = _differences(text, merged)
    if differs:
        return None, f"the edited text would not read back as the merge ({differs})"
    return text, ""


def _replace(text: str, source: str, path: Sdf.Path) -> str | None:
    """``text`` with the statements of ``path`` (a property, or an added prim) as in
    ``source``: in the place of the old ones, or at the start (properties) or end
    (prims) of the owning prim's body."""
    parent = path.GetPrimPath() if path.IsPropertyPath() else path.GetParentPath()
    body = _find_prim(text, parent)
    if body is None:
        return None
    kind = "property" if path.IsPropertyPath() else "prim"
    old = [s for s in statements(text, *body) if s.kind == kind and s.name == path.name]
    chunk, have = _statement_text(source, path)
    chunk = _reindent(chunk, have, _indent(text, body, parent.pathElementCount))
    nl = "\r\n" if "\r\n" in text else "\n"
    chunk = chunk.replace("\n", nl) if nl != "\n" else chunk
    comment = _trailing_comment(text, old[0]) if old else None
    if comment and chunk.count("\n") == 1:  # a remark on the old value's line stays
        chunk = chunk.rstrip("\r\n") + "  " + comment + nl
    if old:  # in the place of its first statement; the others (a .connect line) go
        shift = len(chunk) - (old[0].end - old[0].start)
        out = text[:old[0].start] + chunk + text[old[0].end:]
        for s in reversed(old[1:]):
            out = out[:s.start + shift] + out[s.end + shift:]
        return out
    if kind == "property":
        at = text.find("\n", body[0]) + 1 if body[0] < len(text) and \
            text[body[0]:text.find("\n", body[0])].strip() == "" else body[0]
        return text[:at] + chunk + text[at:]
    at = text.rfind("\n", 0, body[1]) + 1 if parent.pathString != "/" else len(text)
    before = text[:at].rstrip(" \t")
    gap = nl if before and not before.endswith(nl + nl) and not before.endswith("{" + nl) \
        else ""
    return text[:at] + gap + chunk + text[at:]


def _canonical(layer: Sdf.Layer) -> dict:
    """Every spec's fields and values, child order left out: two layers that compose the
    same way (whatever order their properties are written in) are equal."""
    out = {}
    skip = {"primChildren", "properties", "primOrder", "propertyOrder", "variantSetChildren"}

    def visit(path: Sdf.Path) -> None:
        spec = layer.GetObjectAtPath(path)
        if spec is None or not hasattr(spec, "ListInfoKeys"):
            return
        values = {key: (list(layer.subLayerOffsets) if key == "subLayerOffsets" else
                        spec.GetInfo(key)) for key in spec.ListInfoKeys() if key not in skip}
        out[str(path)] = {key: _plain(v) for key, v in values.items()
                          if not (isinstance(v, dict) and not v)}  # {} is no data
    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return out


#: The item lists of an Sdf list op (``apiSchemas``, a relationship's targets).
_LIST_OP_FIELDS = ("isExplicit", "explicitItems", "addedItems", "prependedItems",
                   "appendedItems", "deletedItems", "orderedItems")


def _plain(value):
    """A field's value as plain comparable data: a list op by its item lists, a
    dictionary by its sorted items, anything else by its ``repr`` (TypeError where that
    names only an object's address: not comparable, so not certain)."""
    if all(hasattr(value, f) for f in _LIST_OP_FIELDS):
        return tuple(_plain(getattr(value, f)) for f in _LIST_OP_FIELDS)
    if isinstance(value, dict):
        return tuple(sorted((str(k), _plain(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return tuple(_plain(v) for v in value)
    text = repr(value)
    if " object at 0x" in text:
        raise TypeError(f"no comparable form of {type(value).__name__}")
    return text


def _differences(text: str, merged: Sdf.Layer) -> str:
    """Where ``text`` does not read back as ``merged`` (a few spec paths), "" where it
    does."""
    check = layer_of_text(text)
    if check is None:
        return "USD does not read it"
    try:
        have, want = _canonical(check), _canonical(merged)
    except TypeError:  # a field Python cannot read: not certain, so not equal
        return "a field that cannot be compared"
    paths = sorted(p for p in set(have) | set(want) if have.get(p) != want.get(p))
    return ", ".join(paths[:3]) + (" ..." if len(paths) > 3 else "")
