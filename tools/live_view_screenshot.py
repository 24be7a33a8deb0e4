"""Screenshots of the live view in headless Chromium against a real ``lumitrace serve`` on
a copy of a stage: the page as it loads (the framed photometric solid), then comparing an
edit with the revision before it (pinned), the map's difference view on, a part picked.

    python tools/live_view_screenshot.py [--stage stages/downlight.usda] [--out DIR]
                                         [--target FILE.ies|.ldt] [--photons N]
                                         [--edit PRIM PROPERTY VALUE] [--part NAME]

Writes ``live-view.png`` (the whole page, comparing), ``live-view-solid.png`` (the 3D view
as loaded), ``live-view-compare.png`` (the compare, polar and map panels) into ``--out``
(default: the current folder). ``--target``: compare with that file instead of the pinned
revision; ``--edit``: the edit made (default: the demo's reflector, specular reflectance
0.72); ``--part``: the part picked (default: the Reflector).
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from headless_browser import browser, until  # noqa: E402
from service_process import Service  # noqa: E402

REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"


def _element_png(driver, ids: list[str], path: Path) -> None:
    """One picture of the page's region covering the elements ``ids``."""
    import io

    import matplotlib.image as mpimg
    import numpy as np

    full = mpimg.imread(io.BytesIO(driver.get_screenshot_as_png()), format="png")
    ratio = driver.execute_script("return window.devicePixelRatio") or 1
    boxes = [driver.execute_script(
        "const r = document.getElementById(arguments[0]).getBoundingClientRect();"
        "return [r.left + scrollX, r.top + scrollY, r.right + scrollX, r.bottom + scrollY];",
        i) for i in ids]
    x0, y0 = (int(min(b[k] for b in boxes) * ratio) for k in (0, 1))
    x1, y1 = (int(max(b[k] for b in boxes) * ratio) for k in (2, 3))
    mpimg.imsave(path, np.ascontiguousarray(full[y0:y1, x0:x1]))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--stage", type=Path, default=HERE.parent / "stages" / "downlight.usda")
    p.add_argument("--out", type=Path, default=Path("."))
    p.add_argument("--target", type=Path, default=None)
    p.add_argument("--photons", type=int, default=400_000)
    p.add_argument("--edit", nargs=3, metavar=("PRIM", "PROPERTY", "VALUE"),
                   default=[REFLECTOR, "lumitrace:specularReflectance", "0.72"])
    p.add_argument("--part", default="Reflector")
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / args.stage.name
        shutil.copy(args.stage, stage)
        with Service(stage, "--photons", args.photons, "--resolution", "32", "--out",
                     Path(tmp) / "out", "--no-sublayer") as service:
            service.wait_done(0, pictures=False, timeout=600)
            driver = browser(1400, 1900)
            try:
                driver.get(service.url)
                until(driver, "lumitrace.preview && lumitrace.geometry && lumitrace.framed && "
                              "lumitrace.frames > 5", timeout=120)
                time.sleep(0.5)  # a few frames of the framed view
                driver.find_element("id", "view3d-panel").screenshot(
                    str(args.out / "live-view-solid.png"))
                if args.target is not None:
                    text = args.target.read_text(encoding="latin-1")
                    driver.execute_script("return loadTarget(arguments[0], arguments[1])",
                                          args.target.name, text)
                    until(driver, "lumitrace.comparison")
                else:
                    driver.find_element("id", "pin").click()
                    until(driver, "lumitrace.reference")
                prim, prop, value = args.edit
                revision = service.client.set(prim, prop, float(value))["revision"]
                service.wait_done(revision, pictures=False, timeout=600)
                until(driver, f"lumitrace.preview.header.revision === {revision} && "
                              f"lumitrace.preview.header.photons === "
                              f"{service.client.status()['photons']}", timeout=120)
                driver.find_element("css selector",
                                    "input[name=map-kind][value=difference]").click()
                index = driver.execute_script(
                    "return lumitrace.scene.parts.findIndex(p => p.path.endsWith(arguments[0]))",
                    "/" + args.part)
                driver.execute_script(f"selectPart({index})")
                time.sleep(0.5)
                driver.save_screenshot(str(args.out / "live-view.png"))
                _element_png(driver, ["compare-panel", "polar-panel", "map-panel"],
                             args.out / "live-view-compare.png")
            finally:
                driver.quit()
    for name in ("live-view.png", "live-view-solid.png", "live-view-compare.png"):
        print(args.out / name)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
