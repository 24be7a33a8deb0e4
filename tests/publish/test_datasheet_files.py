"""``lumitrace datasheet`` keeps a trace's rules: it replaces only the files its record says
lumitrace wrote for this stage (never a user's own page), its HTML and PDF are published
together or not at all, and it embeds only the pictures the result layer vouches for by
their SHA-256, drawing them again otherwise (a symlink to a text file, a truncated PNG)."""
from __future__ import annotations

import base64
import io
import json
import os
import re
import shutil
import subprocess
import sys
from argparse import Namespace
from pathlib import Path

import pytest
from helpers.paths import REFERENCE

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _lumitrace(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lumitrace", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def traced(tmp_path_factory):
    """The isotropic stage traced with its pictures: its folder."""
    folder = tmp_path_factory.mktemp("datasheet")
    shutil.copy(REFERENCE / "isotropic.usda", folder / "iso.usda")
    p = _lumitrace("trace", folder / "iso.usda", "--photons", 20_000, "--resolution", 8,
                   "--no-progress", "--quiet")
    assert p.returncode == 0, p.stderr
    assert (folder / "iso.solid.png").read_bytes().startswith(PNG_SIGNATURE)
    return folder


def _copy(traced: Path, tmp_path: Path) -> Path:
    """A copy of the traced folder (each test its own): the stage in it."""
    folder = tmp_path / "stage"
    shutil.copytree(traced, folder)
    return folder / "iso.usda"


def _images(html: Path) -> list[bytes]:
    """The PNGs a page embeds, in order."""
    return [base64.b64decode(m) for m in
            re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html.read_text())]


def _whole_png(data: bytes) -> bool:
    from PIL import Image

    if not (data.startswith(PNG_SIGNATURE) and data.endswith(b"IEND\xaeB`\x82")):
        return False
    Image.open(io.BytesIO(data)).load()
    return True


def test_a_users_own_page_is_never_replaced(traced, tmp_path):
    stage = _copy(traced, tmp_path)
    out = tmp_path / "sheets"
    out.mkdir()
    mine = out / "iso.datasheet.html"
    mine.write_text("<p>my own notes</p>\n")
    p = _lumitrace("datasheet", stage, "--out", out)
    errors = [ln for ln in p.stderr.splitlines() if ln.startswith("lumitrace: error")]
    assert p.returncode == 2 and len(errors) == 1 and str(mine) in errors[0], p.stderr
    assert mine.read_text() == "<p>my own notes</p>\n"
    assert sorted(os.listdir(out)) == ["iso.datasheet.html"]  # nothing else written
    # its own files it replaces; one changed since is the user's again
    mine.unlink()
    assert _lumitrace("datasheet", stage, "--out", out).returncode == 0
    record = json.loads((out / "iso.datasheet.json").read_text())
    assert set(record["files"]) == {"iso.datasheet.html", "iso.datasheet.pdf"}
    assert record["stage"] == "../stage/iso.usda" and record["fromPublished"] is True
    assert _lumitrace("datasheet", stage, "--out", out).returncode == 0
    with open(out / "iso.datasheet.pdf", "ab") as fh:
        fh.write(b"% annotated by hand\n")
    before = {f: (out / f).read_bytes() for f in os.listdir(out)}
    p = _lumitrace("datasheet", stage, "--out", out)
    assert p.returncode == 2 and "iso.datasheet.pdf: changed since lumitrace wrote it" \
        in p.stderr, p.stderr
    assert {f: (out / f).read_bytes() for f in os.listdir(out)} == before
    # a trace's own folder holds its datasheet (trace --deliverables): refused there
    p = _lumitrace("datasheet", stage, "--out", stage.parent)
    assert p.returncode == 2 and "holds the results of a trace" in p.stderr, p.stderr
    assert not (stage.parent / "iso.datasheet.html").exists()


def test_the_page_and_the_pdf_are_published_together_or_not_at_all(traced, tmp_path,
                                                                   monkeypatch):
    """The PDF fails after the page is drawn: the earlier datasheet stays, both files as
    they were, and nothing staged is left."""
    from lumitrace.errors import LumitraceError
    from lumitrace.publish import datasheet_pdf
    from lumitrace.report import datasheet_command

    stage = _copy(traced, tmp_path)
    out = tmp_path / "sheets"
    assert _lumitrace("datasheet", stage, "--out", out).returncode == 0
    before = {f: (out / f).read_bytes() for f in os.listdir(out)}
    assert set(before) == {"iso.datasheet.html", "iso.datasheet.pdf", "iso.datasheet.json"}

    def broken(data, when=None):
        raise LumitraceError("the PDF could not be drawn")

    monkeypatch.setattr(datasheet_pdf, "datasheet_pdf", broken)
    args = Namespace(stage=stage, results=None, out=out, photons=2e4, seed=0, threads=1,
                     json=True, bug_forward=None)
    with pytest.raises(LumitraceError, match="the PDF could not be drawn"):
        datasheet_command.command(args)
    assert {f: (out / f).read_bytes() for f in os.listdir(out)} == before


@pytest.mark.parametrize("damage", ["symlink to a text file", "truncated"])
def test_only_pictures_the_result_layer_vouches_for_are_embedded(traced, tmp_path, damage):
    stage = _copy(traced, tmp_path)
    solid = stage.with_name("iso.solid.png")
    published = solid.read_bytes()
    p = _lumitrace("datasheet", stage, "--json")
    assert p.returncode == 0, p.stderr
    said = json.loads(p.stdout.splitlines()[-1])
    assert said["solid_redrawn"] is False
    assert _images(Path(said["datasheet_html"]))[0] == published  # vouched: embedded as is
    secret = stage.with_name("secret.txt")
    secret.write_text("not a picture: a text the page must never carry\n")
    solid.unlink()
    if damage == "truncated":
        solid.write_bytes(published[:len(published) // 2])
    else:
        solid.symlink_to(secret)
    p = _lumitrace("datasheet", stage, "--json")
    assert p.returncode == 0, p.stderr
    said = json.loads(p.stdout.splitlines()[-1])
    html, pdf = Path(said["datasheet_html"]), Path(said["datasheet_pdf"])
    assert said["solid_redrawn"] is True and pdf.read_bytes().startswith(b"%PDF")
    assert base64.b64encode(secret.read_bytes()).decode() not in html.read_text()
    drawn = _images(html)[0]  # drawn again: whole (maybe the very bytes published)
    assert drawn != solid.read_bytes() and _whole_png(drawn)
