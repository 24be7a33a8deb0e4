"""The luminaire's own data (manufacturer, names, catalogue number, lamp, power, colour
rendering; CCT from the traced colour) and the measured opening's shape, written into the
IES and LDT files and read back by independent readers (``pyldt``, ``eulumdat-ies``) and
our own; bad values are one error naming the property."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.paths import ROOT
from helpers.stages import with_attributes

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)
from lumitrace.photometry.eulumdat import read_ldt
from lumitrace.photometry.lm63 import read_ies

INFO = {"lumitrace:manufacturer": ("string", "Acme Lighting GmbH"),
        "lumitrace:luminaireName": ("string", "Warm Downlight 120"),
        "lumitrace:catalogueNumber": ("string", "AL-DL120-930"),
        "lumitrace:lampDescription": ("string", "LED module 930"),
        "lumitrace:inputPower": ("double", 13.5),
        "lumitrace:colourRenderingIndex": ("double", 92.0)}


def _trace(stage: Path, *extra):
    p = subprocess.run([sys.executable, "-m", "lumitrace", "trace", str(stage), "--photons",
                        "300000", "--resolution", "16", "--no-progress", "--no-pictures",
                        "--json", *extra], capture_output=True, text=True, timeout=300)
    return p.returncode, p.stdout, p.stderr


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    folder = tmp_path_factory.mktemp("metadata")
    stage = with_attributes(ROOT / "stages" / "warm_downlight.usda", folder / "warm.usda", INFO)
    code, out, err = _trace(stage)
    assert code == 0, err
    return stage, json.loads(out.strip().splitlines()[-1])


def test_the_ies_file_carries_the_luminaires_data_and_a_round_opening(warm):
    stage, summary = warm
    ies = read_ies(stage.with_name("warm.ies"))
    kw = ies.keywords
    assert kw["MANUFAC"] == "Acme Lighting GmbH" and kw["LUMCAT"] == "AL-DL120-930"
    assert kw["LUMINAIRE"] == "Warm Downlight 120" and kw["LAMP"] == "LED module 930"
    assert ies.input_watts == pytest.approx(13.5)
    cct = summary["colour"]["cct_K"]
    assert kw["_CCT"] == f"{cct:.0f} K"
    # a circle (LM-63-2019 Table 1): width = length < 0, the measured diameter
    opening = summary["photometry"]["luminous_opening"]
    assert ies.width < 0 and ies.length < 0 and ies.width == pytest.approx(ies.length, rel=0.02)
    assert -ies.length == pytest.approx(opening[0], abs=1e-4)


def test_the_ldt_file_carries_them_as_pyldt_reads_it(warm):
    pyldt = pytest.importorskip("pyldt")
    stage, summary = warm
    h = pyldt.LdtReader.read(str(stage.with_name("warm.ldt"))).header
    assert h.company == "Acme Lighting GmbH"
    assert h.luminaire_name == "Warm Downlight 120" and h.luminaire_number == "AL-DL120-930"
    assert h.file_name == "warm.ldt"
    assert h.lamp_types == ["LED module 930"] and h.lamp_watt == [pytest.approx(13.5)]
    assert h.lamp_cct == [f"{summary['colour']['cct_K']:.0f} K"] and h.lamp_cri == ["92"]
    # the luminaire's body is its bounding box; the luminous area a circle (width 0)
    assert (h.length, h.width, h.height) == (pytest.approx(150.0), pytest.approx(150.0),
                                             pytest.approx(77.0))
    opening = summary["photometry"]["luminous_opening"]
    assert h.width_lum_area == 0.0
    assert h.length_lum_area == pytest.approx(1000 * opening[0], rel=0.02)
    ours = read_ldt(stage.with_name("warm.ldt"))
    assert ours.company == "Acme Lighting GmbH" and ours.name == "Warm Downlight 120"


def test_eulumdat_ies_reads_our_ies_with_its_data(warm):
    eulumdat_ies = pytest.importorskip("eulumdat_ies")
    stage, _ = warm
    h = eulumdat_ies.ies_to_ldt(str(stage.with_name("warm.ies"))).header
    assert h.company == "Acme Lighting GmbH" and h.luminaire_name == "Warm Downlight 120"
    assert h.luminaire_number == "AL-DL120-930" and h.lamp_watt == [pytest.approx(13.5)]
    assert h.length_lum_area == pytest.approx(h.width_lum_area)  # a circle's diameter


def test_the_stand_in_light_has_the_opening_s_area(warm):
    from pxr import Sdf

    stage, summary = warm
    layer = Sdf.Layer.FindOrOpen(str(stage.with_name("warm.lumitrace.usda")))
    light = Sdf.Path("/Luminaire{lumitraceRepresentation=photometric}"
                     "lumitracePhotometricLight.inputs:radius")
    radius = layer.GetAttributeAtPath(light).default * layer.pseudoRoot.GetInfo(
        "metersPerUnit")
    diameter = summary["photometry"]["luminous_opening"][0]
    assert 2 * radius == pytest.approx(diameter, rel=0.02)  # a circle of the same area


def test_a_rectangular_opening_stays_rectangular(tmp_path):
    stage = tmp_path / "louvre.usda"
    shutil.copy(ROOT / "stages" / "louvre.usda", stage)
    code, out, err = _trace(stage)
    assert code == 0, err
    ies = read_ies(tmp_path / "louvre.ies")
    assert ies.width > 0 and ies.length > 0 and ies.length > 1.5 * ies.width
    assert read_ies(tmp_path / "louvre.ies").keywords["MANUFAC"] == "unknown"


@pytest.mark.parametrize("name, kind, value, words", [
    ("lumitrace:inputPower", "double", -5.0, ">= 0"),
    ("lumitrace:colourRenderingIndex", "double", 150.0, "at most 100"),
    ("lumitrace:inputPower", "double", float("nan"), "finite"),
])
def test_bad_luminaire_data_is_one_error_naming_the_property(tmp_path, name, kind, value,
                                                              words):
    stage = with_attributes(ROOT / "stages" / "downlight.usda", tmp_path / "dl.usda",
                            {name: (kind, value)})
    code, _, err = _trace(stage)
    lines = [ln for ln in err.splitlines() if ln.startswith("lumitrace: error")]
    assert code == 2 and len(lines) == 1 and name in lines[0] and words in lines[0], err
