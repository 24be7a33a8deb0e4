"""Embree through its C API, a geometry per part, against embreex's one geometry: the same
triangle at the same float32 distance for every ray, an edited part rebuilt alone and
giving what a fresh build gives, and embreex serving where the library is not found."""
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lumitrace.stage.reader import read_stage
from lumitrace.trace import embree
from lumitrace.trace.job import BatchJob
from lumitrace.trace.prepared import embree_scene, prepare
from lumitrace.trace.tracer import trace_batch

STAGES = Path(__file__).resolve().parents[2] / "stages"
pytestmark = pytest.mark.skipif(embree.library() is None,
                                reason="Embree's library not found beside embreex")


def _traced_rays(ps, photons=20000):
    """The float32 rays the tracer sent to Embree for a few of the scene's lights."""
    rays = []
    for e in range(min(len(ps.scene.emitters), 3)):
        rays += trace_batch(ps, BatchJob(e, 0, photons, 5, 16), record_rays=True).rays
    return np.concatenate([r[0] for r in rays]), np.concatenate([r[1] for r in rays])


def _triangles(ps, scene=None):
    tri = (np.asarray((scene or ps.scene).triangles, np.float64) - ps.center) / ps.scale
    return np.ascontiguousarray(tri, dtype=np.float32)


def _same_hits(a, b):
    hit = b["primID"] >= 0
    assert np.array_equal(a["primID"], b["primID"])
    assert np.array_equal(a["tfar"][hit], b["tfar"][hit])  # embreex's misses say 1e37
    assert np.isinf(a["tfar"][~hit]).all()
    return int(hit.sum())


@pytest.mark.parametrize("stage", ["louvre.usda", "downlight.usda",
                                   "reference/integrating_sphere.usda",
                                   "reference/fresnel_slab.usda"])
def test_a_geometry_per_part_hits_what_embreex_hits(stage):
    ps = prepare(read_stage(STAGES / stage))
    assert isinstance(ps.embree, embree.PartScene)
    o, d = _traced_rays(ps)
    bare = embree_scene(_triangles(ps), (), parts=False)
    assert _same_hits(ps.intersect(o, d), bare.run(o, d, output=1)) > 0.2 * len(o)


def test_an_edited_part_is_rebuilt_alone_and_hits_as_a_fresh_build():
    scene = read_stage(STAGES / "louvre.usda")
    ps = prepare(scene)
    o, d = _traced_rays(ps)
    before = ps.intersect(o, d)
    tri = np.asarray(scene.triangles, np.float64).copy()
    blade = int(np.argmax(np.bincount(scene.part_index)))  # a part with triangles
    tri[np.asarray(scene.part_index) == blade] += (0.0, 0.002, 0.0)  # moved 2 mm
    moved = dataclasses.replace(scene, triangles=tri)
    updated = prepare(moved, ps.frame, previous=ps)
    assert updated.embree is ps.embree and updated.embree.rebuilt == [blade]
    fresh = prepare(moved, ps.frame)
    assert fresh.embree is not ps.embree and len(fresh.embree.rebuilt) > 1
    now = updated.intersect(o, d)
    _same_hits(now, fresh.intersect(o, d))
    _same_hits(now, embree_scene(_triangles(ps, moved), (), parts=False).run(o, d, output=1))
    assert (now["primID"] != before["primID"]).sum() > 100  # the blade moved in their way
    # unchanged triangles rebuild nothing; a new part layout is not an update
    assert prepare(moved, ps.frame, previous=updated).embree.rebuilt == []
    assert not ps.embree.update(_triangles(ps, moved), np.zeros(len(tri), np.int64))


def test_without_the_library_embreex_traces_the_same_photons(monkeypatch):
    scene = read_stage(STAGES / "downlight.usda")
    job = BatchJob(0, 0, 20000, 9, 16)
    ours = trace_batch(prepare(scene), job, records=True)
    monkeypatch.setattr(embree, "library", lambda: None)
    monkeypatch.setattr("lumitrace.trace.prepared.library", lambda: None)
    ps = prepare(scene)
    assert not isinstance(ps.embree, embree.PartScene)
    theirs = trace_batch(ps, job, records=True)
    assert np.array_equal(ours.counts, theirs.counts)
    assert (ours.absorbed, ours.cut, ours.segments) == (theirs.absorbed, theirs.cut,
                                                        theirs.segments)
    assert np.array_equal(ours.records.cells, theirs.records.cells)
