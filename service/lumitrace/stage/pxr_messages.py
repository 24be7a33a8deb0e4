"""The readable part of USD's error texts, without loading USD: the publishers, which
write layers only when a run asks for them, import it at start."""
from __future__ import annotations

import re

#: USD's C++ namespace as it appears in its messages.
NAMESPACE = re.compile(r"pxrInternal_v\d+_\d+(?:_\d+)?__pxrReserved__::")


def _safe_str(value) -> str:
    try:
        return str(value)
    except UnicodeDecodeError:
        return "(message not readable: it quotes bytes that are not UTF-8)"


def tf_message(error) -> str:
    """The readable part of a pxr error (Tf.ErrorException or a composition error)."""
    try:
        text = str(error)
    except UnicodeDecodeError:  # a message quoting bytes that are not UTF-8
        text = " ".join(a.decode("utf-8", "replace") if isinstance(a, bytes) else
                        _safe_str(a) for a in getattr(error, "args", ()))
    text = NAMESPACE.sub("", text).strip()
    messages = []
    for chunk in re.split(r"\s*Error in ", text):
        _, sep, body = chunk.partition(" : '")
        if sep:
            messages.append(body.strip().rstrip("'"))
    message = messages[0] if messages else text or "(USD gave no readable message)"
    # parser internals between "parse error" and the offending text
    message = re.sub(r" matching .*? at '", " at '", message, flags=re.DOTALL)
    return " ".join(message.split())[:300]
