"""The Python API page's example runs as written and measures what a Lambertian disc of
known flux gives."""
from __future__ import annotations

import math
import re

import pytest

from helpers.paths import ROOT


def test_the_api_pages_example_traces_an_in_memory_stage(tmp_path, monkeypatch, capsys):
    page = (ROOT / "docs" / "reference" / "api.md").read_text()
    code = re.search(r"```python\n(.*?)\n```", page, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(code, "docs/reference/api.md", "exec"), scope)
    record = scope["record"]
    out = tmp_path / "api-results"
    assert (out / "Lamp.ies").is_file() and record["ies"] == str(out / "Lamp.ies")
    assert (out / "Lamp.lumitrace.usda").is_file()
    # a one-sided Lambertian disc of luminance 1000 nits and radius 1 cm (a float32
    # attribute): flux = pi L A
    flux = math.pi * 1000.0 * math.pi * 0.01 ** 2
    assert record["luminous_flux"] == pytest.approx(flux, rel=1e-6)
    peak = flux / math.pi
    assert abs(record["peak_intensity"] - peak) < 4 * record["peak_intensity_error"]
    assert "+-" in capsys.readouterr().out
