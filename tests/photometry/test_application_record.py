"""The UGR, luminance, BUG and illuminance figures in the one result record: the --json
summary (strict JSON), the result layer and the values the modules compute."""
from __future__ import annotations

import json
import math
import shutil

import pytest
from pxr import Usd

from lumitrace.photometry.bug import bug_rating
from lumitrace.photometry.distribution import photometry_of
from lumitrace.photometry.luminance import luminance_table
from lumitrace.photometry.ugr import ugr_table
from lumitrace.publish.outputs import write_outputs
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage
from helpers.paths import STAGES


def test_demo_record_carries_the_application_figures(tmp_path):
    stage = tmp_path / "downlight.usda"
    shutil.copy(STAGES / "downlight.usda", stage)
    scene = read_stage(stage)
    result = run(scene, TraceSettings(photons=200_000, resolution=16, threads=2))
    record = write_outputs(result, tmp_path / "out", pictures=False)
    ph = photometry_of(scene, result.accumulator)
    table = ugr_table(ph.grid, ph.opening)
    assert (record["ugr_4h8h_70_50_20"], record["ugr_4h8h_70_50_20_error"]) == \
        table.catalogue()
    assert record["ugr_table"]["crosswise"][10][0] == round(table.crosswise[10, 0], 4)
    assert len(record["ugr_table"]["rooms_h"]) == 19
    lum = luminance_table(ph.grid, ph.opening)
    assert record["luminance_screen_max"] == lum.screen_max
    assert record["bug_rating"] == bug_rating(result.accumulator).text
    summary = json.loads(json.dumps(record.summary(), allow_nan=False))
    p = summary["photometry"]
    for key in ("ugr_table", "ugr_4h8h_70_50_20", "ugr_4h8h_70_50_20_error",
                "luminance_table", "luminance_screen_limits", "bug_rating",
                "bug_zone_lumens", "bug_zone_lumens_error", "cone_diagram", "isolux"):
        assert p[key] is not None, key
    assert p["bug_zone_lumens"]["UL"] == 0.0  # the downlight sends nothing up
    layer = Usd.Stage.Open(str(tmp_path / "out" / "downlight.lumitrace.usda"))
    prim = layer.GetDefaultPrim()
    get = lambda name: prim.GetAttribute(f"lumitrace:result:{name}").Get()  # noqa: E731
    assert get("ugr4H8H") == pytest.approx(record["ugr_4h8h_70_50_20"], rel=1e-12)
    assert get("ugr4H8HError") == pytest.approx(record["ugr_4h8h_70_50_20_error"], rel=1e-12)
    assert get("bugRating") == record["bug_rating"]
    assert math.isfinite(get("screenLuminanceMax"))
