"""Text edit of a ``.usda`` root layer: put one entry first in its ``subLayers``, keeping
every comment and all formatting, and check the edit against an Sdf round trip."""
from __future__ import annotations

from ..stage.usda_scan import layer_of_text, skip_token


def insert_sublayer_text(text: str, entry: str | None, root, remove: tuple[str, ...] = ()
                         ) -> str | None:
    """``text`` with ``@entry@`` first in its ``subLayers`` (None: no entry added) and the
    entries ``remove`` taken out, or ``None`` when the edit is not certain to equal
    ``root`` (the layer as read by Sdf) so edited."""
    from pxr import Sdf

    try:
        candidate = text
        for old in remove:
            candidate = _remove_entry(candidate, old)
            if candidate is None:
                return None
        if entry is not None:
            candidate = _edit_header(candidate, entry)
    except ValueError:
        return None
    if candidate is None:
        return None
    expected = Sdf.Layer.CreateAnonymous(".usda")
    expected.TransferContent(root)
    for old in remove:
        expected.subLayerPaths.remove(old)
    if entry is not None:
        expected.subLayerPaths.insert(0, entry)
    check = layer_of_text(candidate)
    if check is None or check.ExportToString() != expected.ExportToString():
        return None
    return candidate


def sublayer_entries(text: str) -> list[str] | None:
    """The entries of a ``.usda`` text's header ``subLayers``, read without USD; None
    where the list is not plain asset paths between commas (a layer offset, an ``@@@``
    path) or the header cannot be scanned: then USD reads it."""
    start = _header_start(text)
    if start is None:
        return []
    try:
        _, i = _scan_block(text, start)
    except ValueError:
        return None
    if i is None:
        return []
    entries: list[str] = []
    while True:
        i += 1
        while i < len(text) and text[i] in " \t\r\n":
            i += 1
        if i >= len(text):
            return None
        if text[i] == "]" and not entries:
            return entries
        if not text.startswith("@", i) or text.startswith("@@@", i):
            return None
        j = skip_token(text, i)
        if j >= len(text) or text[j - 1] != "@" or j - i < 2:
            return None
        entries.append(text[i + 1:j - 1])
        while j < len(text) and text[j] in " \t\r\n":
            j += 1
        if text.startswith("]", j):
            return entries
        if not text.startswith(",", j):
            return None
        i = j


def _remove_entry(text: str, entry: str) -> str | None:
    """``text`` without the ``@entry@`` of its header's ``subLayers`` (and the comma or
    the line that held it); None where it is not found there."""
    start = _header_start(text)
    if start is None:
        return None
    close, sub_open = _scan_block(text, start)
    if sub_open is None:
        return None
    at = text.find(f"@{entry}@", sub_open, close)
    if at < 0:
        return None
    end = at + len(entry) + 2
    j = end
    while j < close and text[j] in " \t":
        j += 1
    if j < close and text[j] == ",":
        end = j + 1
    else:  # the last entry: drop the comma before it
        k = at - 1
        while k > sub_open and text[k] in " \t\r\n":
            k -= 1
        if text[k] == ",":
            at = k
    line_start = text.rfind("\n", 0, at) + 1
    line_end = text.find("\n", end)
    if text[line_start:at].strip() == "" and line_end >= 0 and \
            text[end:line_end].strip() == "":
        return text[:line_start] + text[line_end + 1:]
    return text[:at] + text[end:]


def _after_header_line(text: str) -> tuple[int, int] | None:
    """(the index after the ``#usda`` line, the index of the first character after it
    that is not blank or a comment line); None for text of one line."""
    end = text.find("\n")
    if end < 0:
        return None
    i = end + 1
    while i < len(text):
        if text[i] in " \t\r\n":
            i += 1
        elif text[i] == "#":
            j = text.find("\n", i)
            i = len(text) if j < 0 else j + 1
        else:
            break
    return end + 1, i


def _header_start(text: str) -> int | None:
    """Index of the ``(`` opening the layer metadata block (None: no block)."""
    at = _after_header_line(text)
    return at[1] if at is not None and at[1] < len(text) and text[at[1]] == "(" else None


def _edit_header(text: str, entry: str) -> str | None:
    nl = "\r\n" if "\r\n" in text else "\n"
    at = _after_header_line(text)
    if at is None:
        return None
    pos, i = at  # blank and comment lines between the header and the metadata block
    item = f"@{entry}@"
    if i >= len(text) or text[i] != "(":
        block = f"({nl}    subLayers = [{nl}        {item}{nl}    ]{nl}){nl}"
        return text[:pos] + block + text[pos:]
    close, sub_open = _scan_block(text, i)
    if sub_open is not None:
        j = sub_open + 1
        while j < len(text) and text[j] in " \t\r\n":
            j += 1
        if j < len(text) and text[j] == "]":     # empty list
            return text[:sub_open + 1] + f"{nl}        {item}{nl}    " + text[j:]
        if text[sub_open + 1] in "\r\n":              # one entry per line
            return text[:sub_open + 1] + f"{nl}        {item}," + text[sub_open + 1:]
        return text[:sub_open + 1] + f"{item}, " + text[sub_open + 1:]
    line_start = text.rfind("\n", i, close) + 1
    if line_start > i and text[line_start:close].strip() == "":
        return (text[:line_start] + f"    subLayers = [{nl}        {item}{nl}    ]{nl}"
                + text[line_start:])
    return text[:close] + f"{nl}    subLayers = [{nl}        {item}{nl}    ]{nl}" + text[close:]


def _scan_block(text: str, start: int) -> tuple[int, int | None]:
    """Scan the layer metadata block opening at ``text[start] == '('``: return the index of
    its closing parenthesis and of the ``[`` opening a top-level ``subLayers`` list (or
    None). Strings, asset paths, prim paths and comments are skipped."""
    depth = 0
    sub_open = None
    i = start
    n = len(text)
    while i < n:
        c = text[i]
        j = skip_token(text, i)  # strings, asset paths, prim paths and comments
        if j != i:
            i = j
            continue
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
            if depth == 0:
                return i, sub_open
        elif depth == 1 and sub_open is None and text.startswith("subLayers", i) \
                and not (text[i - 1].isalnum() or text[i - 1] in "_:"):
            j = i + len("subLayers")
            while j < n and text[j] in " \t":
                j += 1
            if j < n and text[j] == "=":
                j += 1
                while j < n and text[j] in " \t\r\n":
                    j += 1
                if j < n and text[j] == "[":
                    sub_open = j
                    depth += 1
                    i = j + 1
                    continue
        i += 1
    raise ValueError("unterminated layer metadata block")
