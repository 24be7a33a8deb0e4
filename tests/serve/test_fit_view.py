"""A fit started from the live view as a designer does it (real headless Chromium, real
``lumitrace serve``): the mirror cup served at reflectance 0.7, its own LDT traced at 0.95
loaded as the target in Compare, the mirror's reflectance ticked in the Editor (its range
the schema's, 0 to 1); Start; the merit curve and the best's polar curves against the
target's drawn as the fit's events come; the confirmed best recovers the reflectance,
Apply best makes it a revision of the session, the Editor then showing the value, and
Undo takes it back."""
from __future__ import annotations


import pytest
from helpers.browser import CHROMIUM, DRIVER, SKIP_WHY, browser, severe, until
from helpers.fit_stages import mirror_cup, mirror_cup_target
from service_process import Service

pytest.importorskip("selenium.webdriver", reason="selenium is not installed")
if not (CHROMIUM and DRIVER):
    pytest.skip(SKIP_WHY, allow_module_level=True)

FAST = ("--photons", "40000", "--resolution", "32", "--threads", "2")
MIRROR = "/Luminaire/Materials/Mirror"
REFLECTANCE = f"{MIRROR}.lumitrace:specularReflectance"


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    root = tmp_path_factory.mktemp("fit-view")
    ldt = mirror_cup_target(root)
    stage = mirror_cup(root / "cup.usda", 0.7, wall_z=0.0)  # the wall placed by an op
    with Service(stage, *FAST, "--out", root / "out") as service:
        service.wait_done(0, pictures=False)
        yield service, ldt


def test_a_fit_from_the_page_shows_its_merit_and_curves_and_applies_its_best(served,
                                                                           tmp_path):
    service, ldt = served
    page = browser()
    try:
        page.get(service.url)
        until(page, "window.lumitrace && lumitrace.preview && lumitrace.scene")
        page.find_element("id", "target-file").send_keys(str(ldt))
        until(page, "document.getElementById('fit-target').textContent.includes('truth.ldt')")
        # the wall, bound to the mirror, in the Editor; its reflectance ticked for the fit
        page.execute_script("""
            const sel = document.getElementById('part-select');
            const wall = lumitrace.scene.parts.findIndex((p) => p.path === '/Luminaire/Wall');
            sel.value = String(wall);
            sel.dispatchEvent(new Event('change'));""")
        tick = until(page, f"document.querySelector('[data-vary=\"{REFLECTANCE}\"]')")
        tick.click()
        row = until(page, f"document.querySelector('#fit-params tr[data-name=\"{REFLECTANCE}\"]')")
        ends = [i.get_attribute("value") for i in row.find_elements("css selector", "input")]
        assert [float(v) for v in ends] == [0.0, 1.0]  # the schema's range
        # a component of the wall's translate op: ticked and unticked again
        z = "/Luminaire/Wall.xformOp:translate[2]"
        page.find_element("css selector", f'[data-vary="{z}"]').click()
        row = until(page, f"document.querySelector('#fit-params tr[data-name=\"{z}\"]')")
        lo, hi = (float(i.get_attribute("value"))
                  for i in row.find_elements("css selector", "input"))
        assert lo < 0.0 < hi and hi == pytest.approx(-lo)  # about the wall's place, 0
        row.find_element("css selector", "[data-remove]").click()
        until(page, f"!document.querySelector('#fit-params tr[data-name=\"{z}\"]')")
        assert not page.find_element("css selector", f'[data-vary="{z}"]').is_selected()
        page.execute_script("""
            document.getElementById('fit-evaluations').value = '40';
            document.getElementById('fit-photons').value = '16384';
            document.getElementById('fit-start').click();""")
        until(page, "lumitrace.fit && lumitrace.fit.state === 'done'", timeout=300)
        until(page, "document.querySelectorAll('#fit-polar path.best').length === 2")
        fit = page.execute_script("return lumitrace.fit")
        assert fit["error"] is None and len(fit["history"]) >= 3
        best = fit["summary"]["best"][REFLECTANCE]
        assert best == pytest.approx(0.95, abs=0.05)
        assert page.find_elements("css selector", "#fit-polar path.target")
        assert page.find_element("css selector", "#fit-merit polyline")
        state = page.find_element("id", "fit-state").text
        assert "done" in state and "confirmed: merit" in state
        page.find_element("id", "fit-panel").screenshot(str(tmp_path / "fit-panel.png"))
        page.find_element("id", "fit-apply").click()
        revision = until(page, "lumitrace.fit.applied")
        service.wait_done(revision, pictures=False)
        until(page, f"lumitrace.scene && lumitrace.scene.revision >= {revision}")
        until(page, f"Math.abs(lumitrace.scene.materials.find((m) => m.path === '{MIRROR}')"
                    f".specularReflectance - {best}) < 1e-6")  # (a float attribute)
        assert "applied as revision" in page.find_element("id", "fit-state").text
        # Undo takes the fit's best back to the value the fit started from
        page.find_element("id", "undo").click()
        until(page, f"Math.abs(lumitrace.scene.materials.find((m) => m.path === '{MIRROR}')"
                    f".specularReflectance - 0.7) < 1e-6")
        assert not severe(page)
    finally:
        page.quit()
