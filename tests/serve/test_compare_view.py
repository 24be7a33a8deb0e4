"""Comparing in the live view (real headless Chromium, real ``lumitrace serve``): a pinned
revision against an edit, every key figure's difference and its combined standard error as
computed here from the two frames the service serves, the verdict on the noise, the reference
in the polar curve and the difference map; a kept revision picked from the list; a target
EULUMDAT file as the reference (its figures as the service's reader computes them), and a
file that is none refused with its name."""
from __future__ import annotations

import math
import shutil
import urllib.request

import numpy as np
import pytest
from helpers.browser import CHROMIUM, DRIVER, SKIP_WHY, browser, severe, until
from helpers.paths import ROOT
from service_process import Service

from lumitrace.serve.viewer import read_frame

pytest.importorskip("selenium.webdriver", reason="selenium is not installed")
if not (CHROMIUM and DRIVER):
    pytest.skip(SKIP_WHY, allow_module_level=True)

FAST = ("--photons", "150000", "--resolution", "32", "--threads", "2")
REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
#: (figure, difference in percent of the reference or in the figure's unit, unit)
KEYS = (("luminous_flux", "relative", "%"), ("light_output_ratio", "relative", "%"),
        ("peak_intensity", "relative", "%"), ("beam_angle_c0_c180", "absolute", "°"),
        ("beam_angle_c90_c270", "absolute", "°"), ("field_angle_c0_c180", "absolute", "°"),
        ("field_angle_c90_c270", "absolute", "°"), ("ugr_4h8h_70_50_20", "absolute", ""),
        ("ugr_4h8h_70_50_20_endwise", "absolute", ""))


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    stage = tmp_path_factory.mktemp("compare") / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage)
    with Service(stage, *FAST) as service:
        service.wait_done(0, pictures=False)
        yield service


@pytest.fixture(scope="module")
def page(served):
    driver = browser()
    try:
        driver.get(served.url)
        until(driver, "window.lumitrace && lumitrace.preview && lumitrace.scene")
        yield driver
    finally:
        driver.quit()


def _frame(url: str) -> tuple[dict, dict]:
    with urllib.request.urlopen(url) as r:
        return read_frame(r.read())


def expected(now: dict, ref: dict, scale: float = 1.0) -> dict:
    """Each key figure's difference, its combined standard error and whether it lies within
    two of them, from the figures of the design (``now``) and of the reference (its
    intensities times ``scale``)."""
    out = {}
    for key, kind, _ in KEYS:
        a, ea, b, eb = now[key], now[key + "_error"], ref[key], ref[key + "_error"]
        if key in ("luminous_flux", "peak_intensity"):
            b, eb = b * scale, eb * scale
        if key.startswith("ugr"):
            b += 8 * math.log10(scale)
        if kind == "relative":
            d, e = 100 * (a / b - 1), 100 * math.hypot(ea, a * eb / b) / b
        else:
            d, e = a - b, math.hypot(ea, eb)
        out[key] = (d, e, abs(d) <= 2 * e)
    return out


def _shown(d: float, e: float, unit: str) -> str:
    n = min(4, max(0, 1 - math.floor(math.log10(e)))) if e > 0 else 2
    v = f"{abs(d):.{n}f}"
    sign = "" if float(v) == 0 else "+" if d > 0 else "-"
    return f"{sign}{v} ± {e:.{n}f}" + ("" if not unit else unit if unit == "°" else " " + unit)


def _check_rows(page, want: dict) -> list[dict]:
    rows = {r["key"]: r for r in page.execute_script("return lumitrace.comparison.rows")}
    units = {k: u for k, _, u in KEYS}
    for key, (d, e, within) in want.items():
        row = rows[key]
        assert row["difference"]["value"] == pytest.approx(d, rel=1e-9, abs=1e-12), key
        assert row["difference"]["error"] == pytest.approx(e, rel=1e-9, abs=1e-12), key
        assert row["within"] is within, key
        assert row["text"] == _shown(d, e, units[key]), key
        cell = page.find_element("css selector", f"#differences tr[data-key={key}]").text
        assert row["text"] in cell
        assert ("within the noise" if within else "beyond the noise") in cell
    return list(rows.values())


def test_a_pinned_revision_against_an_edit(page, served):
    page.find_element("id", "pin").click()
    until(page, "lumitrace.reference && lumitrace.reference.revision === 0")
    revision = served.client.set(REFLECTOR, "lumitrace:specularReflectance", 0.6)["revision"]
    status = served.wait_done(revision, pictures=False)
    until(page, f"lumitrace.preview.header.revision === {revision} && "
                f"lumitrace.preview.header.photons === {status['photons']} && "
                f"lumitrace.comparison")
    ref_h, ref = _frame(served.url + "revisions/0/preview")
    now_h, now = _frame(served.url + "preview")
    assert ref_h["revision"] == 0 and now_h["revision"] == revision
    want = expected(now_h["figures"], ref_h["figures"])
    rows = _check_rows(page, want)
    # a darker reflector: less flux out, beyond the noise, and the page says so
    assert want["luminous_flux"][0] < 0 and not want["luminous_flux"][2]
    beyond = [r["label"] for r in rows if r["within"] is False]
    verdict = page.find_element("id", "noise-verdict").text
    assert f"{len(beyond)} of {len(rows)} differences beyond the noise" in verdict
    assert "luminous flux" in verdict
    # the reference in the polar curve, in cd/klm of its own lamp flux
    polar = page.execute_script("return lumitrace.polar.reference")
    i0 = int(np.argmin(np.abs(np.asarray(ref_h["c"]) - 0.0)))
    np.testing.assert_allclose(np.asarray(polar["planes"]["0"]["cd"]),
                               ref["grid"][i0], rtol=1e-6)
    assert polar["per_klm"] == pytest.approx(1000 / ref_h["lamp_lumens"])
    assert page.execute_script("return document.querySelectorAll('#polar path.reference')"
                               ".length") == 2
    # the map's difference view: now - reference, its scale the largest difference
    page.find_element("css selector", "input[name=map-kind][value=difference]").click()
    shown = page.execute_script("return lumitrace.map")
    assert shown["kind"] == "difference"
    assert shown["max"] == pytest.approx(float(np.abs(now["filtered"] - ref["filtered"]).max()),
                                         rel=1e-5)
    assert severe(page) == []


def test_a_kept_revision_compared_with_itself_is_within_the_noise(page, served):
    revision = served.client.status()["revision"]
    until(page, f"[...document.querySelectorAll('#revision-select option')]"
                f".some(o => o.value === '{revision}')")
    from selenium.webdriver.support.select import Select

    Select(page.find_element("id", "revision-select")).select_by_value(str(revision))
    until(page, f"lumitrace.reference && lumitrace.reference.revision === {revision} && "
                f"lumitrace.comparison && lumitrace.comparison.reference.startsWith("
                f"'revision {revision}')")
    rows = page.execute_script("return lumitrace.comparison.rows")
    assert all(r["difference"]["value"] == 0 and r["within"] for r in rows)
    assert page.find_element("id", "noise-verdict").text.startswith(
        "Every difference is within the noise")


def test_a_target_file_is_the_reference_and_a_file_that_is_none_is_refused(page, served,
                                                                          tmp_path):
    from lumitrace.photometry.target import read_target, target_figures

    ldt = served.client.results()["outputs"]["ldt"]
    target = tmp_path / "target.ldt"
    shutil.copy(ldt, target)
    page.find_element("id", "target-file").send_keys(str(target))
    until(page, "lumitrace.comparison && lumitrace.comparison.kind === 'file'")
    now = page.execute_script("return lumitrace.preview.header")
    theirs = read_target("target.ldt", target.read_text(encoding="latin-1"))
    assert page.execute_script("return lumitrace.reference.frame.header.lamp_lumens") == \
        pytest.approx(theirs.lamp_lumens)
    scale = now["lamp_lumens"] / theirs.lamp_lumens
    _check_rows(page, expected(now["figures"], target_figures(theirs), scale))
    assert "target.ldt (LDT" in page.find_element("id", "reference-name").text
    # a file that is not a photometric file: its name and what is wrong; the reference stays
    bad = tmp_path / "notes.ldt"
    bad.write_text("these are my notes\n")
    page.find_element("id", "target-file").send_keys(str(bad))
    problem = until(page, "document.getElementById('compare-problem').textContent")
    assert "notes.ldt" in problem
    assert page.execute_script("return lumitrace.comparison.reference").startswith("target.ldt")
