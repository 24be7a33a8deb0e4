"""The documentation site: Sphinx with MyST Markdown pages.

Build it strictly (any warning fails) from the repository's root:

    .venv/bin/sphinx-build -W -q docs site

The reference pages (USD schema, scene-delta protocol, command line, result record) are
generated from their sources as the site builds (``gen_reference.py``); the Python API
comes from the docstrings (autodoc). The site's navigation is :data:`NAV` below.
"""
from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS))
sys.path.insert(0, str(DOCS.parent / "service"))  # autodoc on a checkout without an install

import gen_reference  # noqa: E402

project = "lumitrace"
author = "the lumitrace authors"
copyright = "the lumitrace authors"
release = version = __import__("lumitrace").__version__

extensions = ["myst_parser", "sphinx.ext.autodoc"]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence", "attrs_inline", "deflist"]
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True}
html_theme = "furo"
html_title = "lumitrace"
html_static_path: list[str] = []
suppress_warnings: list[str] = []

#: The site's navigation: section caption -> pages (paths under docs/, without ``.md``),
#: one line a page. A name ending in ``?`` is a page included where it exists (one being
#: written elsewhere); every other page must exist, and a page under docs/ listed nowhere
#: fails the build.
NAV: dict[str, list[str]] = {
    "Start": [
        "getting-started",
    ],
    "Guides": [
        "guide/modelling",
        "guide/colour",
        "guide/tracing",
        "symmetry?",
        "guide/outputs",
        "guide/deliverables",
        "deliverables?",
        "guide/service",
        "service-security?",
        "files-and-safety?",
        "guide/viewer",
        "live-view?",
        "guide/sweeps",
        "fit?",
        "guide/dcc",
        "blender?",
    ],
    "Reference": [
        "reference/cli",
        "reference/schema",
        "reference/protocol",
        "reference/record",
        "reference/api",
    ],
    "Explanation": [
        "explanation/measurement",
        "explanation/files-you-ship",
        "explanation/accuracy",
        "explanation/performance",
        "explanation/architecture",
    ],
    "Project": [
        "changelog",
    ],
}

#: Pages whose body is generated from the sources as the site builds (their file in
#: docs/ holds only a comment saying so).
GENERATED = {page[:-3]: make for page, make in gen_reference.PAGES.items()}


def _toctrees() -> str:
    """The index page's tables of contents, from :data:`NAV`."""
    out = []
    for caption, pages in NAV.items():
        present = [p.rstrip("?") for p in pages
                   if not p.endswith("?") or (DOCS / f"{p[:-1]}.md").is_file()]
        out.append("\n```{toctree}\n:caption: " + caption + "\n:maxdepth: 1\n\n"
                   + "\n".join(present) + "\n```\n")
    return "".join(out)


def _source_read(app, docname: str, source: list[str]) -> None:
    if docname in GENERATED:
        source[0] = GENERATED[docname]()
    elif docname == root_doc:
        source[0] += _toctrees()


def _always_outdated(app, env, added, changed, removed):
    """Generated pages are read again on every build: their sources are not their files."""
    return [name for name in GENERATED if name in env.found_docs]


def setup(app):
    app.connect("source-read", _source_read)
    app.connect("env-get-outdated", _always_outdated)
    return {"parallel_read_safe": True}
