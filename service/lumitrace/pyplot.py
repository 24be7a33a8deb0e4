"""matplotlib's pyplot on the Agg backend (files, no display), for every picture we draw.

Loading pyplot writes, for each of matplotlib's ~100 Artist classes, a ``set()`` docstring
that lists every property it has: about 0.1 s of the 0.5 s a run's first picture spends
loading matplotlib. A lumitrace command's own process never shows a docstring, so the
command line calls :func:`short_setter_docs` and those are left short; a program that
imports lumitrace as a library keeps matplotlib's as they are.
"""
from __future__ import annotations

import sys

_short_docs = False


def short_setter_docs() -> None:
    """Have pyplot load without the Artist ``set()`` property lists (a command's process)."""
    global _short_docs
    _short_docs = True


def pyplot():
    """``matplotlib.pyplot``, with the Agg backend chosen."""
    import matplotlib

    matplotlib.use("Agg")
    if not _short_docs or "matplotlib.pyplot" in sys.modules:
        import matplotlib.pyplot as plt

        return plt
    import matplotlib.artist as artist

    kwdoc = getattr(artist, "kwdoc", None)
    if kwdoc is not None:
        artist.kwdoc = lambda _artist: "(see the class's set_* methods)"
    try:
        import matplotlib.pyplot as plt
    finally:
        if kwdoc is not None:
            artist.kwdoc = kwdoc
    return plt
