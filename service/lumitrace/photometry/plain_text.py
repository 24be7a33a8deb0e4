"""Text as a line of a photometric file: one line, in the file's character set.

IES LM-63 and EULUMDAT files are lines of text, their fields found by line number (LDT) or
by a keyword at the start of a line (IES): a line break inside a field shifts every field
after it. So whatever text reaches them (the luminaire's data, which the stage reader
checked, but also file and prim names) is written as one line: control characters and
line breaks become spaces and runs of white space one space. Characters outside the
file's character set (ASCII for IES, ISO 8859-1 for EULUMDAT) lose their accents where
that makes them fit (``é`` -> ``e``, ``ž`` -> ``z``) and become ``?`` otherwise.
"""
from __future__ import annotations

import unicodedata


def _fits(ch: str, charset: str) -> bool:
    try:
        ch.encode(charset)
    except UnicodeEncodeError:
        return False
    return True


def _folded(ch: str, charset: str) -> str:
    """``ch`` in ``charset``: itself, its compatibility decomposition without combining
    marks (``é`` -> ``e``, ``ﬁ`` -> ``fi``, a no-break space -> a space), or ``?``."""
    if _fits(ch, charset):
        return ch
    base = "".join(c for c in unicodedata.normalize("NFKD", ch)
                   if not unicodedata.combining(c))
    return base if base and all(_fits(c, charset) for c in base) else "?"


def one_line(text: str, charset: str = "ascii", limit: int | None = None) -> str:
    """``text`` as one line of ``charset``: control characters, line breaks and white space
    runs become one space, the ends are stripped, every other character is folded into the
    charset; at most ``limit`` characters (cut, then stripped again)."""
    out = []
    for ch in str(text):
        code = ord(ch)
        if ch.isspace() or code < 0x20 or 0x7F <= code <= 0x9F or 0xD800 <= code <= 0xDFFF:
            ch = " " if not 0xD800 <= code <= 0xDFFF else "?"
        out.append(_folded(ch, charset))
    line = " ".join("".join(out).split())
    return line if limit is None else line[:limit].rstrip()
