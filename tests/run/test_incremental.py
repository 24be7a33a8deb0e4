"""Selective retracing is exact: after any sequence of edits of every class, the map
refined incrementally (only the photons an edit can change retraced) equals a fresh trace of
the edited stage with the same seed, photons and tracing frame, count for count."""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pxr import Gf, Usd, UsdGeom
from stress_cases import FOUR_PARTS, add_disk_light, four_part_luminaire

from lumitrace.run.incremental import retrace, select
from lumitrace.run.session import Refinement, run
from lumitrace.run.settings import TraceSettings
from lumitrace.stage.reader import read_stage
from lumitrace.trace.prepared import TracingFrame, prepare
from lumitrace.trace.records import RECORD_BYTES
from lumitrace.trace.tracer import trace_batch

SETTINGS = TraceSettings(photons=30_000, resolution=8, seed=11, threads=1, batch_size=4096)
PARTS = FOUR_PARTS


def _luminaire(path: Path) -> Path:
    four_part_luminaire(path)
    return path


def _refine(r: Refinement, ps) -> None:
    while True:
        jobs = r.next_jobs()
        if not jobs:
            return
        r.add_round([trace_batch(ps, j, records=True) for j in jobs])


def _edit(stage: Usd.Stage, kind: str, part: str, x: float) -> None:
    prim = stage.GetPrimAtPath(part)
    if kind == "material":
        name = ("lumitrace:specularReflectance" if prim.HasAttribute(
            "lumitrace:specularReflectance") else "lumitrace:reflectance")
        if part == PARTS[1]:
            name = "lumitrace:ior"
            x = 1.2 + x
        prim.GetAttribute(name).Set(float(x))
    elif kind == "move":
        xf = UsdGeom.Xformable(prim)
        xf.ClearXformOpOrder()
        xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble, "edit").Set(
            Gf.Vec3d(0.0, 0.004 * (x - 0.5), 0.003 * x))
    elif kind == "points":
        mesh = UsdGeom.Mesh(prim)
        pts = np.array(mesh.GetPointsAttr().Get(), dtype=np.float64) * (0.9 + 0.2 * x)
        mesh.GetPointsAttr().Set([Gf.Vec3f(*map(float, p)) for p in pts])
    elif kind == "active":
        prim.SetActive(not prim.IsActive())
    elif kind == "light":
        light = UsdGeom.Xformable(stage.GetPrimAtPath("/Luminaire/Led"))
        light.ClearXformOpOrder()
        light.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble, "edit").Set(
            Gf.Vec3d(0.002 * x, 0.0, -0.001))
    elif kind == "display":
        UsdGeom.Gprim(prim).CreateDisplayColorAttr([Gf.Vec3f(x, x, x)])


EDITS = st.lists(st.tuples(st.sampled_from(["material", "move", "points", "active", "light",
                                            "display"]),
                           st.sampled_from(PARTS), st.floats(0.05, 0.95)),
                 min_size=1, max_size=3)


@settings(max_examples=12, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(EDITS)
def test_incremental_retrace_equals_a_fresh_trace(edits):
    with tempfile.TemporaryDirectory() as tmp:
        path, scene, frame, r, stage = _traced_luminaire(Path(tmp) / "lum.usda")
        ps = prepare(scene, frame)
        for kind, part, x in edits:
            _edit(stage, kind, part, x)
            stage.GetRootLayer().Save()
            new = read_stage(path)
            sel = select(r.records, r.scene, new, frame)
            assert sel.restart is None, sel.restart
            ps = prepare(new, frame, previous=ps)  # only the edited parts' Embree geometry
            retrace(r, new, sel, lambda work: [trace_batch(ps, j, photons=ids, records=True)
                                               for j, ids in work], 4096)
            fresh = run(new, SETTINGS, frame=frame)
            assert np.array_equal(r.accumulator.counts(), fresh.accumulator.counts()), kind
            a, b = r.accumulator.emitters[0], fresh.accumulator.emitters[0]
            assert (a.photons, a.absorbed, a.cut, a.segments) == \
                (b.photons, b.absorbed, b.cut, b.segments)
            assert np.array_equal(a.cells, b.cells), kind  # the goniophotometer's counts too
            np.testing.assert_allclose(r.accumulator.intensity(),
                                       fresh.accumulator.intensity(), rtol=1e-12)
            if kind == "display":
                assert sel.photons == 0  # nothing the tracer sees: nothing retraced


def test_moved_parts_of_a_two_level_scene_retrace_as_a_fresh_trace(tmp_path, monkeypatch):
    # each part its own Embree scene: a move is a new transform of the part's structure,
    # and the fresh trace builds the same structure from the same frames
    from lumitrace.trace import embree

    monkeypatch.setattr(embree, "TWO_LEVEL_TRIANGLES", 0)
    path, scene, frame, r, stage = _traced_luminaire(tmp_path / "lum.usda")
    ps = prepare(scene, frame)
    assert ps.embree.two_level
    for kind, part, x in (("move", PARTS[0], 0.3), ("move", PARTS[1], 0.7),
                          ("material", PARTS[0], 0.6), ("move", PARTS[0], 0.9)):
        _edit(stage, kind, part, x)
        stage.GetRootLayer().Save()
        new = read_stage(path)
        sel = select(r.records, r.scene, new, frame)
        ps = prepare(new, frame, previous=ps)
        g = new.parts.index(part)
        assert (ps.embree.rebuilt, ps.embree.moved) == ([], [g] if kind == "move" else [])
        retrace(r, new, sel, lambda work: [trace_batch(ps, j, photons=ids, records=True)
                                           for j, ids in work], 4096)
        fresh = run(new, SETTINGS, frame=frame)
        assert np.array_equal(r.accumulator.counts(), fresh.accumulator.counts()), kind
        assert np.array_equal(r.accumulator.emitters[0].cells, fresh.accumulator.emitters[0].cells)


def _traced_luminaire(path: Path, records_cap: int = 1 << 30):
    """The test luminaire traced with records: (path, scene, frame, refinement, stage)."""
    _luminaire(path)
    scene = read_stage(path)
    frame = TracingFrame.of(scene)
    r = Refinement(scene, SETTINGS, records_cap=records_cap)
    _refine(r, prepare(scene, frame))
    return path, scene, frame, r, Usd.Stage.Open(str(path))


def test_a_material_edit_retraces_only_the_photons_that_met_the_part(tmp_path):
    path, scene, frame, r, stage = _traced_luminaire(tmp_path / "lum.usda")
    _edit(stage, "material", PARTS[3], 0.2)  # the small baffle below the lens
    stage.GetRootLayer().Save()
    new = read_stage(path)
    sel = select(r.records, r.scene, new, frame)
    assert 0 < sel.photons < 0.5 * SETTINGS.photons
    assert sum(r.nbytes for r in r.records) == SETTINGS.photons * RECORD_BYTES


def test_edits_that_need_a_restart_say_why(tmp_path):
    path, scene, frame, r, stage = _traced_luminaire(tmp_path / "lum.usda")
    UsdGeom.Xformable(stage.GetPrimAtPath(PARTS[2])).AddTranslateOp().Set(Gf.Vec3d(0, 0, 1.0))
    stage.GetRootLayer().Save()
    assert select(r.records, scene, read_stage(path), frame).restart == \
        "geometry moved outside the session's tracing frame"
    add_disk_light(stage, "/Luminaire/Led2", 0.004)
    stage.GetRootLayer().Save()
    assert select(r.records, scene, read_stage(path), frame).restart == \
        "emitters were added or removed"
    small = Refinement(scene, SETTINGS, records_cap=1000)
    _refine(small, prepare(scene, frame))
    assert small.records is None and small.records_dropped
    assert "memory cap" in select(small.records, scene, scene, frame).restart


@pytest.fixture(autouse=True)
def _quiet_warnings():
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


@pytest.mark.parametrize("kind", ["active", "move"])
@pytest.mark.parametrize("part", PARTS)
def test_photons_cut_by_the_depth_limit_are_retraced_when_their_last_part_changes(
        tmp_path, kind, part):
    """At a depth limit of 2 many photons are cut; removing or moving the part a cut photon
    last met changes its fate, so its record holds that last segment too."""
    import dataclasses

    shallow = dataclasses.replace(SETTINGS, max_depth=2)
    path = _luminaire(tmp_path / "lum.usda")
    scene = read_stage(path)
    frame = TracingFrame.of(scene)
    r = Refinement(scene, shallow, records_cap=1 << 30)
    _refine(r, prepare(scene, frame))
    assert r.accumulator.emitters[0].cut > 1000
    stage = Usd.Stage.Open(str(path))
    _edit(stage, kind, part, 0.7)
    stage.GetRootLayer().Save()
    new = read_stage(path)
    sel = select(r.records, r.scene, new, frame)
    ps = prepare(new, frame)
    retrace(r, new, sel, lambda work: [trace_batch(ps, j, photons=ids, records=True)
                                       for j, ids in work], 4096)
    fresh = run(new, shallow, frame=frame)
    a, b = r.accumulator.emitters[0], fresh.accumulator.emitters[0]
    assert (a.cut, a.absorbed) == (b.cut, b.absorbed)
    assert np.array_equal(r.accumulator.counts(), fresh.accumulator.counts())


def _ramp(prim, x: float) -> None:
    """A reflectance spectrum on ``prim`` rising from 0.3 to 0.3 + 0.6 x toward the red."""
    from pxr import Sdf

    prim.CreateAttribute("lumitrace:reflectanceSpectrum", Sdf.ValueTypeNames.Float2Array).Set(
        [Gf.Vec2f(400.0, 0.3), Gf.Vec2f(700.0, 0.3 + 0.6 * float(x))])


COLOUR_EDITS = st.lists(st.tuples(st.sampled_from(["colour", "light colour", "material",
                                                   "move", "active"]),
                                  st.sampled_from(PARTS), st.floats(0.05, 0.95)),
                        min_size=1, max_size=3)


@settings(max_examples=6, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(COLOUR_EDITS)
def test_incremental_retrace_of_a_spectral_scene_equals_a_fresh_trace(edits):
    """With a coloured surface photons carry a spectral throughput: retracing takes their
    recorded X and Z out and traces them again, and X and Z match a fresh trace exactly."""
    from pxr import Sdf

    with tempfile.TemporaryDirectory() as tmp:
        path = _luminaire(Path(tmp) / "lum.usda")
        stage = Usd.Stage.Open(str(path))
        _ramp(stage.GetPrimAtPath(PARTS[2]), 0.8)
        stage.GetPrimAtPath("/Luminaire/Led").CreateAttribute(
            "lumitrace:illuminant", Sdf.ValueTypeNames.String).Set("blackbody 3000")
        stage.GetRootLayer().Save()
        scene = read_stage(path)
        assert scene.colour == "spectral"
        frame = TracingFrame.of(scene)
        r = Refinement(scene, SETTINGS, records_cap=1 << 30)
        ps = prepare(scene, frame)
        _refine(r, ps)
        for kind, part, x in edits:
            if kind == "colour":
                _ramp(stage.GetPrimAtPath(PARTS[2] if part == PARTS[1] else part), x)
            elif kind == "light colour":
                stage.GetPrimAtPath("/Luminaire/Led").GetAttribute(
                    "lumitrace:illuminant").Set(f"blackbody {2500 + 4000 * x:.0f}")
            else:
                _edit(stage, kind, PARTS[3] if part == PARTS[2] and kind == "active" else part,
                      x)
            stage.GetRootLayer().Save()
            new = read_stage(path)
            sel = select(r.records, r.scene, new, frame)
            if sel.restart is not None:  # the coloured part went: no longer spectral
                assert new.colour != "spectral"
                return
            ps = prepare(new, frame, previous=ps)
            retrace(r, new, sel, lambda work: [trace_batch(ps, j, photons=ids, records=True)
                                               for j, ids in work], 4096)
            fresh = run(new, SETTINGS, frame=frame)
            a, b = r.accumulator.emitters[0], fresh.accumulator.emitters[0]
            assert np.array_equal(a.counts, b.counts), kind
            for mine, theirs in zip(a.xz, b.xz):
                assert np.array_equal(mine, theirs), kind


def test_slab_masks_narrow_a_geometry_edit_and_follow_their_definition(tmp_path):
    """Moving a part retraces the photons whose path boxes can meet its new boxes: by the
    64 cells and, along each axis, the 32 slabs; the slabs leave out photons the cells
    alone would take, and every slab mask is the slabs its box spans."""
    from lumitrace.trace.records import SLABS

    path, scene, frame, r, stage = _traced_luminaire(tmp_path / "lum.usda")
    grid = frame.grid
    lo = np.random.default_rng(2).uniform(-1, 1, (3, 500))
    hi = lo + np.random.default_rng(3).uniform(0, 0.5, (3, 500))
    masks = grid.box_slabs(lo, hi)
    for k in range(3):
        a = np.clip(np.floor((lo[k] - grid.lo[k]) / (grid.hi[k] - grid.lo[k]) * SLABS), 0,
                    SLABS - 1)
        b = np.clip(np.floor((hi[k] - grid.lo[k]) / (grid.hi[k] - grid.lo[k]) * SLABS), 0,
                    SLABS - 1)
        want = [sum(1 << s for s in range(int(i), int(j) + 1)) for i, j in zip(a, b)]
        assert masks[:, k].tolist() == want
    _edit(stage, "move", PARTS[3], 0.6)
    stage.GetRootLayer().Save()
    new = read_stage(path)
    sel = select(r.records, r.scene, new, frame)
    from lumitrace.trace.records import part_bits

    rec = r.records[0]
    tri = (new.part_geometry()[PARTS[3]][0] - np.array(frame.center)) / frame.scale
    by_cells = ((rec.parts & part_bits([PARTS[3]])[0]) != 0) | (
        (rec.cells & grid.triangle_cells(tri)) != 0)
    assert 0 < sel.photons < by_cells.sum()
