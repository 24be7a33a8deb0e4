"""The five-minute tour runs as written: the README's examples and the getting-started
page's, each in a fresh copy of the stages (tests/test_docs.py runs the other pages)."""
import pytest

from helpers.doc_examples import TOUR, run_page, work_folder
from helpers.paths import ROOT


@pytest.mark.parametrize("page", TOUR, ids=lambda p: str(p.relative_to(ROOT)))
def test_the_tours_examples_run(page, tmp_path):
    assert run_page(page, work_folder(tmp_path)) >= 5
