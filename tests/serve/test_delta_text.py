"""The luminaire's text and numbers sent to a real service: a control character, a line
break (in a 'set' delta or a layer fragment) or a colour rendering index out of range is a
422 naming the prim, the property and the character, nothing authored; an edits layer saved
on disk with one is reported and the last revision stays; good text reaches the files."""
from __future__ import annotations

import json
import time
import urllib.error
import urllib.request
from pathlib import Path

from service_process import Service

from helpers.paths import ROOT

ISOTROPIC = ROOT / "stages" / "reference" / "isotropic.usda"
FAST = ("--photons", 20_000, "--resolution", 8, "--threads", 1, "--seed", 3,
        "--no-sublayer")


def _post(url: str, deltas: list[dict]) -> tuple[int, dict]:
    req = urllib.request.Request(url + "deltas", data=json.dumps({"deltas": deltas}).encode(),
                                 method="POST", headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def _set(name: str, value) -> dict:
    return {"op": "set", "path": "/Luminaire", "property": name, "value": value}


def _content(path: Path) -> bytes | None:
    return path.read_bytes() if path.exists() else None


def test_bad_luminaire_text_is_a_422_naming_the_character_and_good_text_is_written(tmp_path):
    stage = tmp_path / "iso.usda"
    stage.write_text(ISOTROPIC.read_text())
    edits = tmp_path / "iso.lumitrace-edits.usda"
    fragment = ('#usda 1.0\nover "Luminaire"\n{\n    string lumitrace:luminaireName = '
                '"""Spot\nGmbH"""\n}\n')
    cases = {"colour code": (_set("lumitrace:manufacturer", "ACME\x1b[31m"),
                             "/Luminaire.lumitrace:manufacturer", "U+001B"),
             "line break": (_set("lumitrace:catalogueNumber", "AL-1\r\n2"),
                            "/Luminaire.lumitrace:catalogueNumber", "U+000D"),
             "fragment": ({"op": "layer", "usda": fragment},
                          "/Luminaire.lumitrace:luminaireName", "U+000A"),
             "negative CRI": (_set("lumitrace:colourRenderingIndex", -5),
                              "/Luminaire.lumitrace:colourRenderingIndex", "at least 0")}
    with Service(stage, *FAST) as s:
        s.wait_done(0, pictures=False)
        before = _content(edits)
        for label, (delta, where, said) in cases.items():
            code, payload = _post(s.url, [delta])
            assert code == 422, (label, payload)
            problems = " ".join(f"{p['where']} {p['why']}" for p in payload["problems"])
            assert where in problems and said in problems, (label, payload)
            assert _content(edits) == before, label
        assert s.client.status()["revision"] == 0
        code, payload = _post(s.url, [_set("lumitrace:manufacturer",
                                           "Lichttechnik M\u00fcnchen & Co <Werk 2>")])
        assert code == 200, payload
        s.wait_done(1, pictures=False)
        ldt = (tmp_path / "iso.ldt").read_bytes().decode("latin-1")
        assert ldt.splitlines()[0] == "Lichttechnik M\u00fcnchen & Co <Werk 2>"
        # the edits layer saved by hand with a control character: reported, not traced
        text = edits.read_text()
        assert "M\u00fcnchen" in text
        edits.write_text(text.replace("M\u00fcnchen", "M\\x1bnchen"))
        deadline = time.monotonic() + 60
        errors = []
        while not errors and time.monotonic() < deadline:
            errors = [e for e in s.client.history(0) if e.kind == "error"]
            time.sleep(0.1)
        assert errors, s.stderr
        message = errors[0].data["message"]
        assert "/Luminaire.lumitrace:manufacturer" in message and "U+001B" in message, message
        status = s.client.status()
        assert status["revision"] == 1 and status["written_revision"] == 1
