"""Text in the XML we write (the GLDF's ``product.xml``, the L3D's ``structure.xml``), as
XML 1.0 defines it: ``&``, ``<``, ``>`` and quotes escaped, and a character XML 1.0 cannot
hold (a control character other than tab, line feed and carriage return, a surrogate,
U+FFFE, U+FFFF) written as U+FFFD, the replacement character. The luminaire's own text
never holds one (the stage reader refuses it); file and prim names may."""
from __future__ import annotations

import re

#: Characters outside XML 1.0's ``Char`` production.
_NOT_XML = re.compile("[^\t\n\r\u0020-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")
_ESCAPES = {"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&apos;"}
_SPECIAL = re.compile("[&<>\"']")


def xml_text(text: str) -> str:
    """``text`` as XML 1.0 character data or an attribute value (quotes escaped too)."""
    return _SPECIAL.sub(lambda m: _ESCAPES[m.group()], _NOT_XML.sub("\ufffd", str(text)))
