"""The sweep's overview page (``index.html``) in a real headless Chromium: every case's polar
curve on one common scale (the toggle puts each on its own), and a table of each case's
differences from a chosen one, each with the combined standard error of both and the
verdict on the noise, computed here from the rows."""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from helpers.browser import CHROMIUM, DRIVER, SKIP_WHY, browser, until

from lumitrace.report.sweep_table import DIFFERENCES, overview

pytest.importorskip("selenium.webdriver", reason="selenium is not installed")

GAMMA = np.arange(0.0, 180.0 + 1e-9, 5.0)


def _case(folder, name: str, peak: float, power: float, flux: float, flux_error: float):
    """A sweep row and its photometry file: I = peak cos(gamma)^power below the horizon."""
    cd = np.where(GAMMA <= 90, peak * np.clip(np.cos(np.radians(GAMMA)), 0, None) ** power, 0)
    path = folder / f"{name}.photometry.json"
    path.write_text(json.dumps({"c": [0.0], "gamma": GAMMA.tolist(), "symmetry": "rotational",
                                "candela": [cd.tolist()]}))
    row = {"stage": str(folder / f"{name}.usda"), "variant": "", "folder": str(folder / name),
           "photometry_data": str(path), "photons": 100000, "seconds": 1.0, "converged": True,
           "luminous_flux": flux, "luminous_flux_error": flux_error,
           "light_output_ratio": flux / 1000, "light_output_ratio_error": flux_error / 1000,
           "peak_intensity": peak, "peak_intensity_error": 0.01 * peak,
           "ugr_4h8h_70_50_20": 20.0 + power, "ugr_4h8h_70_50_20_error": 0.3}
    for plane in ("c0_c180", "c90_c270"):
        width = 2 * math.degrees(math.acos(0.5 ** (1 / power)))
        row[f"beam_angle_{plane}"], row[f"beam_angle_{plane}_error"] = width, 0.4
        row[f"field_angle_{plane}"], row[f"field_angle_{plane}_error"] = None, None
    return row


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sweep-page")
    rows = [_case(folder, "wide", 300.0, 1, 900.0, 2.0),
            _case(folder, "narrow", 1200.0, 8, 880.0, 2.0),
            _case(folder, "same", 302.0, 1, 901.0, 2.0)]
    page = folder / "index.html"
    page.write_text(overview(rows, folder))
    return page, rows


def _radius(svg: str) -> float:
    """The farthest point of an SVG's curves from its centre (px)."""
    pts = [tuple(map(float, p.split(","))) for line in re.findall(r'points="([^"]+)"', svg)
           for p in line.split()]
    return max(math.hypot(x - 110, y - 110) for x, y in pts)


def test_every_polar_curve_is_on_one_common_scale_by_default(sweep):
    page, rows = sweep
    text = page.read_text()
    common = re.findall(r'<svg[^>]*class="common".*?</svg>', text)
    own = re.findall(r'<svg[^>]*class="own".*?</svg>', text)
    assert len(common) == len(own) == 3
    r0 = 220 * 0.45
    peaks = [r["peak_intensity"] for r in rows]
    for svg, peak in zip(common, peaks):  # in proportion to each case's peak
        assert _radius(svg) == pytest.approx(r0 * peak / max(peaks), abs=0.1)
    for svg in own:  # each to its own
        assert _radius(svg) == pytest.approx(r0, abs=0.1)


@pytest.fixture(scope="module")
def driver(sweep):
    if not (CHROMIUM and DRIVER):
        pytest.skip(SKIP_WHY)
    d = browser(1200, 1200)
    try:
        d.get(sweep[0].as_uri())
        until(d, "document.querySelectorAll('#differences tr').length > 1")
        yield d
    finally:
        d.quit()


def test_the_toggle_puts_each_curve_on_its_own_scale(driver):
    visible = "return [...document.querySelectorAll('svg.' + arguments[0])].map(" \
              "s => getComputedStyle(s).display !== 'none')"
    assert all(driver.execute_script(visible, "common"))
    assert not any(driver.execute_script(visible, "own"))
    driver.find_element("id", "own-scale").click()
    assert all(driver.execute_script(visible, "own"))
    assert not any(driver.execute_script(visible, "common"))
    driver.find_element("id", "own-scale").click()


def _difference(a, ea, b, eb, kind):
    if a is None or b is None:
        return None
    if kind == "relative":
        return 100 * (a / b - 1), 100 * math.hypot(ea, a * eb / b) / b
    return a - b, math.hypot(ea, eb)


@pytest.mark.parametrize("chosen", [0, 1])
def test_the_table_gives_every_difference_from_the_chosen_case(driver, sweep, chosen):
    from selenium.webdriver.support.select import Select

    _, rows = sweep
    Select(driver.find_element("id", "reference")).select_by_value(str(chosen))
    for i, row in enumerate(rows):
        if i == chosen:
            assert not driver.find_elements("css selector", f"#differences tr[data-case='{i}']")
            continue
        beyond = 0
        for key, _, kind, unit in DIFFERENCES:
            cell = driver.find_element(
                "css selector", f"#differences tr[data-case='{i}'] td[data-key='{key}']")
            ref = rows[chosen]
            got = _difference(row.get(key), row.get(key + "_error"), ref.get(key),
                              ref.get(key + "_error"), kind)
            if got is None:
                assert cell.text == "-"
                continue
            d, e = got
            n = min(4, max(0, 1 - math.floor(math.log10(e))))
            sign = "" if float(f"{abs(d):.{n}f}") == 0 else "+" if d > 0 else "-"
            assert cell.text == f"{sign}{abs(d):.{n}f} ± {e:.{n}f}" + (f" {unit}" if unit
                                                                          else ""), key
            within = abs(d) <= 2 * e
            beyond += not within
            assert cell.get_attribute("class") == ("within" if within else "beyond"), key
        verdict = driver.find_element(
            "css selector", f"#differences tr[data-case='{i}'] td.verdict").text
        assert verdict == (f"{beyond} beyond the noise" if beyond else "all within the noise")
    # the case alike to the wide one is within the noise of it; the narrow one is not
    if chosen == 0:
        assert driver.find_element("css selector", "#differences tr[data-case='2'] "
                                                   "td.verdict").text == "all within the noise"
