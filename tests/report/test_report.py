"""The convergence report: files, figures and the time-to-error bookkeeping."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from lumitrace.report.metrics import psnr, ssim
from lumitrace.report.convergence_report import ReportSettings, crossing_time, run_report
from helpers.paths import ROOT



def testcrossing_time_interpolates_in_log_log():
    t = [1.0, 4.0]
    e = [0.1, 0.025]  # error ~ t^-1
    assert crossing_time(t, e, 0.05) == pytest.approx(2.0)
    assert crossing_time(t, e, 0.2) == 1.0
    assert crossing_time(t, e, 0.01) is None


def test_psnr_and_ssim_of_identical_and_noisy_maps():
    rng = np.random.default_rng(0)
    ref = rng.uniform(10, 20, size=(6 * 16, 16))
    assert psnr(ref, ref) == float("inf")
    assert ssim(ref, ref) == pytest.approx(1.0)
    noisy = ref + rng.normal(0, 2.0, ref.shape)
    assert psnr(noisy, ref) == pytest.approx(10 * np.log10(ref.max() ** 2 / 4.0), abs=0.3)
    assert ssim(noisy, ref) < 0.9


def test_report_on_the_lambertian_disc(tmp_path):
    stage = tmp_path / "disc.usda"
    shutil.copy(ROOT / "stages" / "reference" / "lambertian_disc.usda", stage)
    out = run_report(stage, tmp_path / "rep",
                     ReportSettings(photons=300_000, seconds=None, resolution=16,
                                    thresholds=(0.0, 32.0), threads=2))
    data = json.loads(Path(out["json"]).read_text())
    assert data["photons"] == 300_000
    assert data["reference"].startswith("closed form (lambertian)")
    rows = data["iterations_data"]
    assert len(rows) >= 3 and rows[0]["photons"] < rows[-1]["photons"]
    raw = [r["true"]["0"] for r in rows]
    assert raw[-1] < raw[0]  # converges
    # the raw error falls like 1/sqrt(photons)
    slope = np.polyfit(np.log([r["photons"] for r in rows]), np.log(raw), 1)[0]
    assert -0.6 < slope < -0.4
    # estimated and true errors agree (factor 1.5) once counts are meaningful
    last = rows[-1]
    for key in ("0", "32"):
        assert last["true"][key] / 1.5 <= last["estimated"][key] <= last["true"][key] * 1.5
    for name in ("error_vs_time", "error_vs_photons", "maps"):
        png = Path(out[name]).read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    page = Path(out["html"]).read_text()
    assert "error_vs_time.png" in page and "maps.png" in page
    # the measured figures of the final result, with their errors
    f = data["figures"]
    assert f["luminous_flux"] == pytest.approx(1000.0) and f["upward_flux_fraction"] == 0.0
    assert abs(f["peak_intensity"] - 1000.0 / np.pi) < 4.0 * f["peak_intensity_error"]
    assert data["warnings"] == []
