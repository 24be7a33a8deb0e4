"""The README's Python API example runs as written and measures what a Lambertian disc of
known flux gives."""
from __future__ import annotations

import math
import re

import pytest

from helpers.paths import ROOT


def test_the_readme_example_traces_an_in_memory_stage(tmp_path, capsys):
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Python API", 1)[1]
    code = re.search(r"```python\n(.*?)\n```", section, re.S).group(1)
    scope = {"out_dir": tmp_path}
    exec(compile(code, "README.md (Python API)", "exec"), scope)
    record = scope["record"]
    assert (tmp_path / "Lamp.ies").is_file() and record["ies"] == str(tmp_path / "Lamp.ies")
    assert (tmp_path / "Lamp.lumitrace.usda").is_file()
    # a one-sided Lambertian disc of luminance 1000 nits and radius 1 cm (a float32
    # attribute): flux = pi L A
    flux = math.pi * 1000.0 * math.pi * 0.01 ** 2
    assert record["luminous_flux"] == pytest.approx(flux, rel=1e-6)
    peak = flux / math.pi
    assert abs(record["peak_intensity"] - peak) < 4 * record["peak_intensity_error"]
    assert "+-" in capsys.readouterr().out
