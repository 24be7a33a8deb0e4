"""A long floating-point array in a delta is set through numpy (USD's conversion of a Python
list holds the interpreter for most of a second at 200,000 points): the values authored are
those USD's own conversion gives, bit for bit, and a value of the wrong shape is refused as
a short one is."""
from __future__ import annotations

import random

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

from lumitrace.delta.apply import apply_deltas
from lumitrace.delta.protocol import DeltaError


def _stage():
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.Mesh.Define(stage, "/Mesh")
    edits = Sdf.Layer.CreateAnonymous()
    stage.GetSessionLayer().subLayerPaths.append(edits.identifier)
    return stage, edits


def test_long_arrays_author_the_values_usd_converts():
    rng = random.Random(5)
    points = [[rng.uniform(-60, 60) for _ in range(3)] for _ in range(5000)]
    points[3] = [1, 2, 3]  # whole numbers among floats, as JSON gives them
    widths = [rng.uniform(0, 1) for _ in range(5000)]
    stage, edits = _stage()
    apply_deltas(stage, edits, [
        {"op": "set", "path": "/Mesh", "property": "points", "value": points},
        {"op": "set", "path": "/Mesh", "property": "user:widths", "value": widths,
         "type": "double[]"}], ".")
    ref = Usd.Stage.CreateInMemory()
    mesh = UsdGeom.Mesh.Define(ref, "/Mesh")
    mesh.GetPointsAttr().Set(points)  # USD's own conversion of the list
    got = stage.GetPrimAtPath("/Mesh")
    np.testing.assert_array_equal(np.array(got.GetAttribute("points").Get()),
                                  np.array(mesh.GetPointsAttr().Get()))
    assert list(got.GetAttribute("user:widths").Get()) == widths


@pytest.mark.parametrize("n", [10, 5000])
def test_a_wrong_width_is_refused_long_or_short(n):
    stage, edits = _stage()
    with pytest.raises(DeltaError) as short:
        apply_deltas(stage, edits, [{"op": "set", "path": "/Mesh", "property": "points",
                                     "value": [[0.0, 1.0]] * n}], ".")
    assert "points" in str(short.value) and "point3f[]" in str(short.value)
    assert stage.GetPrimAtPath("/Mesh").GetAttribute("points").Get() is None
