"""pyplot as lumitrace loads it: the Agg backend, and a command's process spared the Artist
``set()`` property lists (a library's user keeps matplotlib's own)."""
from __future__ import annotations

import subprocess
import sys

PROBE = """
import sys
from lumitrace import pyplot as p
if sys.argv[1] == "short":
    p.short_setter_docs()
import matplotlib.artist as artist
original = artist.kwdoc
plt = p.pyplot()
from matplotlib.lines import Line2D
print(plt.get_backend(), artist.kwdoc is original, "markerfacecolor" in Line2D.set.__doc__)
"""


def _probe(mode: str) -> list[str]:
    run = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    return run.stdout.split()


def test_a_commands_pyplot_skips_the_setter_property_lists_and_restores_kwdoc():
    assert _probe("short") == ["Agg", "True", "False"]


def test_a_library_users_pyplot_keeps_matplotlibs_docstrings():
    assert _probe("full") == ["Agg", "True", "True"]
