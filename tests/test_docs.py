"""The documentation: the site builds strictly (any warning fails it), its reference pages
hold every command and schema attribute, and every example of every page runs as written,
page by page, in a fresh copy of the stages (the tour's pages, the README and getting
started, in tests/test_docs_tour.py). The conventions a page uses to say how a block runs
are in docs/explanation/architecture.md."""
from __future__ import annotations

import re
import subprocess
import sys

import pytest

from helpers.doc_examples import DOCS, PAGES, TOUR, blocks, run_page, work_folder

sys.path.insert(0, str(DOCS))
import gen_reference  # noqa: E402  (the reference pages' generator, plain functions)


@pytest.mark.parametrize("page", [p for p in PAGES if p not in TOUR],
                         ids=lambda p: str(p.relative_to(DOCS)))
def test_the_examples_of_the_page_run(page, tmp_path):
    run_page(page, work_folder(tmp_path))


def test_pages_say_how_their_blocks_run():
    """Every comment that speaks to these tests is one they understand, right before a
    block; the illustrative blocks are few."""
    known = re.compile(r"(file \S+|service( \S+)?|stop-service|expect-exit \d+|blender"
                       r"|skip \(.+\))")
    skipped = total = 0
    for page in PAGES:
        text = page.read_text()
        for said in re.findall(r"^<!-- test: (.*) -->$", text, re.M):
            assert known.fullmatch(said), f"{page}: {said!r}"
        for block in blocks(page):
            if block.lang in ("sh", "python", "json", "usda"):
                total += 1
                skipped += block.directive.startswith("skip")
    assert total > 40 and skipped <= total // 4, (skipped, total)


def test_every_command_and_schema_attribute_is_in_the_reference():
    """The generated reference names every subcommand of the parser and every attribute
    of the three API schemas as USD's schema registry knows them (from the generated
    schema, not the file the generator reads)."""
    from pxr import Usd

    import lumitrace  # noqa: F401  (registers the schema)
    from lumitrace.cli import build_parser

    cli = gen_reference.cli_page()
    sub = next(a for a in build_parser()._actions if hasattr(a, "choices") and a.choices)
    for name in sub.choices:
        assert f"## `lumitrace {name}`" in cli, name
    schema = gen_reference.schema_page()
    registry = Usd.SchemaRegistry()
    names = set()
    for api in ("LumitraceMaterialAPI", "LumitraceEmitterAPI", "LumitraceLuminaireAPI"):
        names |= set(registry.FindAppliedAPIPrimDefinition(api).GetPropertyNames())
    assert len(names) > 50
    for name in names:
        assert f"`{name}`" in schema, name
    protocol = gen_reference.protocol_page()
    for op in ("set", "transform", "bind", "add", "remove", "active", "variant", "layer"):
        assert f"## `{op}`" in protocol


def test_the_site_builds_strictly(tmp_path):
    """``sphinx-build -W``: a broken link, a missing page, a bad docstring fail it."""
    for module in ("sphinx", "myst_parser", "furo"):
        pytest.importorskip(module, reason="the docs extra is not installed "
                                           "(pip install -e '.[docs]')")
    site = tmp_path / "site"
    p = subprocess.run([sys.executable, "-m", "sphinx", "-W", "-q", "-E", "-b", "html",
                        str(DOCS), str(site)], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-5000:]
    cli = (site / "reference" / "cli.html").read_text()
    assert "lumitrace trace" in cli and "--target-error" in cli
    assert "lumitrace:luminousFlux" in (site / "reference" / "schema.html").read_text()
    assert "scene_from_stage" in (site / "reference" / "api.html").read_text()
