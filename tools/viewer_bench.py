"""The live view measured in a real headless browser against a real ``lumitrace serve``:
from a material control's change to the first refreshed preview drawn, frames per second
of the 3D view while the map refines, the page's weight and the size of one map refresh.

    python tools/viewer_bench.py [--stage stages/downlight.usda] [--edits 8] [--json]
        [--screenshot PATH]
"""
from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from headless_browser import browser, until  # noqa: E402
from service_process import Service  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stage", type=Path, default=HERE.parent / "stages" / "downlight.usda")
    ap.add_argument("--edits", type=int, default=8)
    ap.add_argument("--photons", type=int, default=2_000_000)
    ap.add_argument("--screenshot", type=Path, default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    folder = Path(tempfile.mkdtemp(prefix="lumitrace-viewer-"))
    stage = folder / args.stage.name
    shutil.copy(args.stage, stage)
    out = {}
    with Service(stage, "--photons", args.photons, "--threads", 2) as service:
        weight = 0
        for name in ("", "page/viewer.js", "page/viewer.css"):
            with urllib.request.urlopen(service.url + name) as r:
                weight += len(r.read())
        driver = browser()
        try:
            t0 = time.perf_counter()
            driver.get(service.url)
            until(driver, "lumitrace.preview && lumitrace.geometry")
            out["first_preview_s"] = time.perf_counter() - t0
            f0, w0 = driver.execute_script("return [lumitrace.frames, performance.now()]")
            time.sleep(3.0)  # the map refines meanwhile
            f1, w1 = driver.execute_script("return [lumitrace.frames, performance.now()]")
            out["fps_while_refining"] = (f1 - f0) / ((w1 - w0) / 1000.0)
            out["preview_bytes"] = driver.execute_script("return lumitrace.preview.bytes")
            index = driver.execute_script(
                "return lumitrace.scene.parts.findIndex(p => p.path.endsWith('Reflector'))")
            driver.execute_script(f"selectPart({index})")
            latencies, phases = [], []
            for k in range(args.edits):
                value = 0.9 - 0.05 * (k % 8)
                n = driver.execute_script("return lumitrace.timings.length")
                el = driver.find_element(
                    "css selector", "#material-box input[data-prop=specularReflectance]")
                driver.execute_script("arguments[0].value = arguments[1];"
                                      "arguments[0].dispatchEvent(new Event('change'));",
                                      el, str(value))
                until(driver, f"lumitrace.timings.length > {n} && "
                              f"lumitrace.timings[{n}].drawn != null")
                t = driver.execute_script(f"return lumitrace.timings[{n}]")
                latencies.append(t["drawn"])
                phases.append({k: t.get(k) for k in ("posted", "evented", "asked", "fetched",
                                                     "drawn")})
                time.sleep(0.5)
            out["edit_to_preview_ms"] = {"median": statistics.median(latencies),
                                         "min": min(latencies), "max": max(latencies),
                                         "all": latencies, "phases": phases}
            if args.screenshot:
                time.sleep(2.0)
                driver.save_screenshot(str(args.screenshot))
        finally:
            driver.quit()
        out["page_bytes"] = weight
    shutil.rmtree(folder, ignore_errors=True)
    if args.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"{k:22s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
