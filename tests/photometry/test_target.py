"""A target photometric file read as a reference (:mod:`lumitrace.photometry.target`): the
figures of a Lambertian distribution written as IES and as EULUMDAT are its closed forms,
the opening's units and shape are read as the formats define them, and text that is not a
photometric file is one clear error naming the file."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lumitrace.errors import LumitraceError
from lumitrace.photometry.eulumdat import format_ldt
from lumitrace.photometry.grid import CGammaGrid
from lumitrace.photometry.lm63 import format_ies
from lumitrace.photometry.target import read_target, target_figures

LAMP = 1250.0  # lm: the file's lamp flux; the luminaire's is 1000 (LOR 0.8)


def _lambertian() -> CGammaGrid:
    """I = (1000 / pi) cos(gamma) below the horizon, on a 2.5 deg grid (rotational)."""
    gamma = np.arange(0.0, 180.0 + 1e-9, 2.5)
    cd = np.where(gamma <= 90.0, 1000.0 / math.pi * np.cos(np.radians(gamma)), 0.0)
    return CGammaGrid(np.array([0.0]), gamma, np.clip(cd, 0.0, None)[None, :], "rotational")


@pytest.mark.parametrize("fmt", ["ies", "ldt"])
def test_a_lambertian_targets_figures_are_its_closed_forms(fmt):
    grid = _lambertian()
    if fmt == "ies":
        text = format_ies(grid, LAMP, width=-0.1, length=-0.1, height=0.0)
    else:
        text = format_ldt(grid.full(), LAMP, "lambertian", {
            "length": 100, "width": 0, "height": 20, "lum_length": 100, "lum_width": 0,
            "lum_height": 0}, dff=1.0, lor=0.8)
    target = read_target(f"lambertian.{fmt}", text)
    assert target.format == fmt and target.lamp_lumens == pytest.approx(LAMP)
    assert target.opening.round and target.opening.length == pytest.approx(0.1)
    assert target.opening.width == pytest.approx(0.1)
    f = target_figures(target)
    # zonal sums of a 2.5 deg grid: the integral of cos within 1e-3
    assert f["luminous_flux"] == pytest.approx(1000.0, rel=1e-3)
    assert f["light_output_ratio"] == pytest.approx(0.8, rel=1e-3)
    # (EULUMDAT holds cd/klm to one decimal)
    assert f["peak_intensity"] == pytest.approx(1000.0 / math.pi, rel=1e-3)
    assert (f["peak_gamma"], f["luminous_flux_error"]) == (0.0, 0.0)
    # half and a tenth of the peak: cos(gamma) = 0.5 and 0.1, linear between 2.5 deg steps
    for plane in ("c0_c180", "c90_c270"):
        assert f[f"beam_angle_{plane}"] == pytest.approx(120.0, abs=0.02)
        assert f[f"field_angle_{plane}"] == pytest.approx(
            2 * math.degrees(math.acos(0.1)), abs=0.05)
    assert 0 < f["ugr_4h8h_70_50_20"] < 40 and f["ugr_4h8h_70_50_20_error"] == 0.0


def test_an_ies_opening_in_feet_is_read_in_metres():
    text = format_ies(_lambertian(), LAMP, 0.5, 1.0, 0.0).replace(
        f"1 {LAMP:.6g} 1 73 1 1 2 ", f"1 {LAMP:.6g} 1 73 1 1 1 ")
    target = read_target("feet.ies", text)
    assert not target.opening.round
    assert (target.opening.width, target.opening.length) == pytest.approx((0.1524, 0.3048))


@pytest.mark.parametrize("name, text, said", [
    ("empty.ies", "", "TILT"),
    ("short.ies", "IES:LM-63-2019\nTILT=NONE\n1 1000 1 3", "incomplete"),
    ("words.ldt", "company\nnot a number\n", "Ityp"),
    ("nan.ies", "IES:LM-63-2019\nTILT=NONE\n1 1000 1 2 1 1 2 0 0 0\n1 1 0\n0 90\n0\n"
                "nan 2\n", "finite"),
    ("dark.ies", "IES:LM-63-2019\nTILT=NONE\n1 1000 1 2 1 1 2 0 0 0\n1 1 0\n0 90\n0\n"
                 "0 -1\n", "emits nothing"),
])
def test_text_that_is_no_photometric_file_is_one_error_naming_it(name, text, said):
    with pytest.raises(LumitraceError) as err:
        read_target(name, text)
    assert name in str(err.value) and said in str(err.value), str(err.value)
