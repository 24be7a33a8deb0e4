"""The live view page in a real headless browser (the system's Chromium, driven by its
chromedriver, WebGL2 by SwiftShader) against a real ``lumitrace serve`` on a free loopback
port: it draws, it shows what the service and the written files say, its edits are deltas
whose effect shows, a refused value changes nothing, a DCC's save shows up, and a token is
asked for and needed."""
from __future__ import annotations

import json
import shutil
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from helpers.browser import CHROMIUM, DRIVER, SKIP_WHY, browser, pixels, until
from helpers.paths import ROOT
from service_process import Service

webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed")
if not (CHROMIUM and DRIVER):
    pytest.skip(SKIP_WHY, allow_module_level=True)

FAST = ("--photons", "120000", "--resolution", "32", "--threads", "2")
_browser = browser


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    folder = tmp_path_factory.mktemp("viewer")
    stage = folder / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage)
    with Service(stage, *FAST) as service:
        service.wait_done(0)
        yield service


@pytest.fixture(scope="module")
def page(served):
    driver = _browser()
    try:
        driver.get(served.url)
        until(driver, "window.lumitrace && lumitrace.preview && lumitrace.geometry && "
                      "lumitrace.frames > 5")
        yield driver
    finally:
        driver.quit()


def test_the_page_draws_3d_map_and_polar_views_without_errors(page, served, tmp_path):
    errors = [e for e in page.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors
    assert page.execute_script("return lumitrace.errors") == []
    for element_id in ("view3d", "map", "polar", "convergence"):
        img = pixels(page.find_element("id", element_id))
        assert img.std() > 0.02, f"{element_id} looks blank"
    page.save_screenshot(str(tmp_path / "page.png"))
    # the binary frames are what the service says they are
    with urllib.request.urlopen(served.url + "preview") as r:
        from lumitrace.serve.viewer import read_frame

        header, arrays = read_frame(r.read())
    assert arrays["filtered"].shape == (91, 181) and arrays["grid"].shape[1] == \
        len(header["gamma"])


def test_the_polar_curve_and_figures_are_the_results_and_the_files(page, served):
    pyldt = pytest.importorskip("pyldt")
    results = served.client.results()
    polar = until(page, "lumitrace.polar && lumitrace.polar.photons === "
                        f"{results['photons']} && lumitrace.polar")
    figures = page.execute_script("return lumitrace.figures")
    ours = results["photometry"]
    for key in ("peak_intensity", "peak_intensity_error", "luminous_flux",
                "beam_angle_c0_c180", "field_angle_c90_c270", "photometry_error"):
        assert figures[key] == pytest.approx(ours[key], rel=1e-9), key
    shown = page.find_element("id", "figures").text
    assert f"{ours['peak_intensity']:.1f} cd ± {ours['peak_intensity_error']:.1f}" in shown
    ldt = pyldt.LdtReader.read(results["outputs"]["ldt"])
    cd_klm = np.asarray(ldt.intensities, dtype=float)
    c0 = np.asarray(polar["planes"]["0"]["cd"]) * polar["per_klm"]
    gammas = np.asarray(polar["gamma"])
    assert len(gammas) == cd_klm.shape[1]
    np.testing.assert_allclose(c0, cd_klm[0], rtol=2e-3, atol=0.05)  # LDT keeps 1 decimal
    sigma = np.asarray(polar["planes"]["0"]["sigma"])
    assert (sigma > 0).any() and np.all(sigma >= 0)


def _set(page, selector: str, value) -> None:
    page.execute_script("const el = document.querySelector(arguments[0]);"  # one script:
                        "el.value = arguments[1];"  # the rows may be rebuilt between calls
                        "el.dispatchEvent(new Event('change'));", selector, str(value))


def _select_part(page, name: str) -> None:
    index = page.execute_script(
        f"return lumitrace.scene.parts.findIndex(p => p.path.endsWith('{name}'))")
    assert index >= 0
    page.execute_script(f"selectPart({index})")


def test_a_darker_reflector_is_a_delta_and_less_light_comes_out(page, served):
    _select_part(page, "Reflector")
    before = served.client.status()["revision"]
    flux_before = page.execute_script("return lumitrace.figures.luminous_flux")
    _set(page, "#material-box input[data-prop=specularReflectance]", 0.2)
    until(page, f"lumitrace.status && lumitrace.status.revision > {before}")
    revision = page.execute_script("return lumitrace.status.revision")
    served.wait_done(revision, pictures=False)
    until(page, f"lumitrace.preview.header.revision === {revision} && "
                f"lumitrace.preview.header.photons === {served.client.status()['photons']}")
    flux_after = page.execute_script("return lumitrace.figures.luminous_flux")
    assert flux_after < 0.95 * flux_before, (flux_before, flux_after)
    timing = page.execute_script(f"return lumitrace.timings.find(t => t.revision === {revision})")
    assert timing["drawn"] is not None and timing["drawn"] > 0
    assert page.execute_script("return lumitrace.undo.length") >= 1


def test_an_out_of_range_value_shows_the_problem_and_changes_nothing(page, served):
    _select_part(page, "Reflector")
    before = served.client.status()["revision"]
    _set(page, "#material-box input[data-prop=reflectance]", 1.7)
    problem = until(page, "document.querySelector('#material-box input[data-prop=reflectance]')"
                          ".closest('.row').querySelector('.problem').textContent")
    assert "reflectance" in problem and "1.7" in problem, problem
    time.sleep(0.3)
    assert served.client.status()["revision"] == before


def test_an_edit_saved_by_another_program_shows_up_in_the_page(page, served):
    stage = served.stage
    text = stage.read_text()
    assert "float lumitrace:luminousFlux = 1200" in text
    before = served.client.status()["revision"]
    stage.write_text(text.replace("float lumitrace:luminousFlux = 1200",
                                  "float lumitrace:luminousFlux = 600"))
    until(page, f"lumitrace.scene && lumitrace.scene.revision > {before} && "
                "lumitrace.scene.emitters[0].flux === 600", timeout=60)
    # read in one script: the editor may rebuild its rows between two WebDriver calls
    shown = page.execute_script("return document.querySelector('#emitter-box input').value")
    assert float(shown) == 600.0


def test_with_a_token_the_page_asks_for_it_and_nothing_works_without(tmp_path):
    stage = tmp_path / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage)
    with Service(stage, *FAST, token="s3cret-token") as service:
        for path in ("status", "preview", "scene", "events"):
            try:
                urllib.request.urlopen(service.url + path)
                pytest.fail(f"/{path} answered without the token")
            except urllib.error.HTTPError as exc:
                assert exc.code == 401
        driver = _browser()
        try:
            driver.get(service.url)
            until(driver, "!document.getElementById('token-box').hidden")
            assert driver.execute_script("return lumitrace.preview") is None
            driver.find_element("id", "token-input").send_keys("s3cret-token")
            driver.find_element("css selector", "#token-form button").click()
            until(driver, "lumitrace.preview && lumitrace.geometry", timeout=90)
            assert "token" not in driver.current_url
            assert driver.execute_script("return lumitrace.status.state") in (
                "tracing", "done", "starting")
        finally:
            driver.quit()
