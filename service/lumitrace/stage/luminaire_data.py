"""What the luminaire's own data (LumitraceLuminaireAPI) may hold, checked where it enters:
the stage reader and the scene deltas refuse a value with one message naming the prim, the
property and the offending character (``/Luminaire.lumitrace:manufacturer: holds a line
break (U+000A LINE FEED) at character 14 ...``).

The text attributes (manufacturer, luminaire name, catalogue number, lamp description) go
into a line of the IES and LDT files and into the GLDF's and L3D's XML, so they are one line
of printable text: no control characters (U+0000-U+001F, U+007F-U+009F: a line break, a
tab, a terminal's colour code), no line or paragraph separators (U+2028, U+2029), no
surrogates or noncharacters U+FFFE and U+FFFF (no XML 1.0 file can hold them), and at most
:data:`MAX_TEXT` characters. What a file's own format cannot hold (an EULUMDAT field's
length, the IES file's ASCII) is the writers' to handle, as their formats define.

The numbers: the input power is finite and at least 0 W (GLDF's ``RatedInputPower``); the
colour rendering index finite in [0, 100] (GLDF's ``ColorRenderingIndex``, EN 12665).
"""
from __future__ import annotations

import math
import numbers
import unicodedata

from ..schema import COLOUR_RENDERING_INDEX, INPUT_POWER, LUMINAIRE_TEXT

#: Most characters of one text attribute (an IES keyword continues over [MORE] lines; an
#: EULUMDAT field holds 78 or fewer and is cut there).
MAX_TEXT = 1000
#: Inclusive ranges of the number attributes.
NUMBER_RANGES = {INPUT_POWER: (0.0, math.inf), COLOUR_RENDERING_INDEX: (0.0, 100.0)}
#: Every attribute of the luminaire's own data.
LUMINAIRE_DATA = (*LUMINAIRE_TEXT, *NUMBER_RANGES)

_CONTROL_NAMES = {0x00: "NUL", 0x09: "CHARACTER TABULATION", 0x0A: "LINE FEED",
                  0x0B: "LINE TABULATION", 0x0C: "FORM FEED", 0x0D: "CARRIAGE RETURN",
                  0x1B: "ESCAPE", 0x7F: "DELETE", 0x85: "NEXT LINE"}
_LINE_BREAKS = {0x0A, 0x0B, 0x0C, 0x0D, 0x85, 0x2028, 0x2029}
_WHY = "it is written into one line of the IES and LDT files and into XML"


def character_label(ch: str) -> str:
    """``U+001B ESCAPE``: a character's code point and name, for messages."""
    code = ord(ch)
    name = _CONTROL_NAMES.get(code) or unicodedata.name(ch, "")
    return f"U+{code:04X}" + (f" {name}" if name else "")


def refused_character(ch: str) -> str | None:
    """What kind of character ``ch`` is where the luminaire's text may not hold it (a line
    break, a control character, ...), or None where it may."""
    code = ord(ch)
    if code in _LINE_BREAKS:
        return "a line break"
    if code < 0x20 or 0x7F <= code <= 0x9F:
        return "a control character"
    if 0xD800 <= code <= 0xDFFF:
        return "a lone surrogate (not a character)"
    if code in (0xFFFE, 0xFFFF):
        return "a noncharacter"
    return None


def text_problem(value) -> str | None:
    """Why ``value`` cannot be the luminaire's text, or None where it can."""
    if not isinstance(value, str):
        return f"must be text, got {type(value).__name__}"
    for i, ch in enumerate(value):
        kind = refused_character(ch)
        if kind is not None:
            return (f"holds {kind} ({character_label(ch)}) at character {i + 1}: {_WHY}; "
                    "remove it")
    if len(value) > MAX_TEXT:
        return f"is {len(value)} characters long, more than {MAX_TEXT}"
    return None


def number_problem(name: str, value) -> str | None:
    """Why ``value`` cannot be the number attribute ``name``, or None where it can."""
    lo, hi = NUMBER_RANGES[name]
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return f"must be a number, got {type(value).__name__}"
    v = float(value)
    if not math.isfinite(v):
        return f"must be finite, got {v}"
    if v < lo or v > hi:
        if math.isinf(hi):
            return f"must be >= {lo:g}, got {v:g}"
        return f"must be at least {lo:g} and at most {hi:g}, got {v:g}"
    return None


def luminaire_data_problem(name: str, value) -> str | None:
    """Why ``value`` cannot be the luminaire attribute ``name`` (one of
    :data:`LUMINAIRE_DATA`), or None where it can, or where ``name`` is none of them."""
    if name in LUMINAIRE_TEXT:
        return text_problem(value)
    if name in NUMBER_RANGES:
        return number_problem(name, value)
    return None
