"""Scanning ``.usda`` text without parsing it: the tokens inside which brackets, quotes and
comment marks mean nothing, so that text editors of a layer (its subLayers, a merge of
edits) find the statements they change and keep everything else byte for byte."""
from __future__ import annotations


def skip_token(text: str, i: int) -> int:
    """The index after a string, asset path, prim path or comment starting at ``i`` (``i``
    itself when none starts there)."""
    c = text[i]
    if c in "\"'":
        q3 = text[i:i + 3]
        if q3 in ('"""', "'''"):
            j = text.find(q3, i + 3)
            if j < 0:
                raise ValueError("unterminated string")
            return j + 3
        j = i + 1
        while j < len(text) and text[j] != c:
            if text[j] == "\n":
                raise ValueError("unterminated string")
            j += 2 if text[j] == "\\" else 1
        return j + 1
    if c == "@":
        close = "@@@" if text.startswith("@@@", i) else "@"
        j = text.find(close, i + len(close))
        return len(text) if j < 0 else j + len(close)
    if c == "<":
        j = text.find(">", i + 1)
        return len(text) if j < 0 else j + 1
    if c == "#":
        j = text.find("\n", i)
        return len(text) if j < 0 else j
    return i


def matching_bracket(text: str, i: int) -> int:
    """The index of the bracket closing the one at ``text[i]`` (brackets in strings, asset
    paths and comments left out)."""
    depth = 0
    while i < len(text):
        j = skip_token(text, i)
        if j != i:
            i = j
            continue
        if text[i] in "([{":
            depth += 1
        elif text[i] in ")]}":
            depth -= 1
            if depth == 0:
                return i
        i += 1
    raise ValueError("unbalanced brackets")


def layer_of_text(text: str):
    """An anonymous Sdf layer holding ``text`` as read by USD, or None where USD does not
    read it (how a text editor checks its edit before writing it)."""
    from pxr import Sdf, Tf

    layer = Sdf.Layer.CreateAnonymous(".usda")
    try:
        return layer if layer.ImportFromString(text) else None
    except Tf.ErrorException:
        return None
