"""Embree through its C API, a geometry of quads per part (one level, or two: each part its
own scene, placed by its own transform), against embreex's one geometry of triangles: the
same triangle for every ray but one that meets a quad's diagonal, at the same float32
distance but for its last bits (two-level: and a grazing ray), an edited part rebuilt alone
and a moved one placed anew unbuilt, each giving exactly what a fresh build gives, a
two-level trace equal to a one-level one photon for photon but for a grazing ray's, and
embreex serving where the library is not found."""
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


#: Share of rays whose hit a two-level scene may decide otherwise than one level: a ray
#: that grazes a triangle's edge is caught by one structure and missed by the other.
EDGE_SHARE = 1e-4
#: How far (normalised units, the luminaire about 1 across) a distance may lie from
#: embreex's: a quad's corners are taken in another order than its triangles' (a few
#: float32 roundings of coordinates about 1), and a two-level scene meets a placed part in
#: the part's own space.
QUAD_ROUNDING, DISTANCE_ROUNDING = 1e-6, 1e-5


def _same_hits(a, b, within=None):
    """Whether the hits ``a`` and ``b`` agree: every ray exactly, or (``b`` embreex's)
    all but :data:`EDGE_SHARE` of them on the same triangle, their distances ``within``
    that many normalised units."""
    hit = b["primID"] >= 0
    if within is not None:
        near = np.abs(a["tfar"].astype(np.float64) - b["tfar"]) <= within
        same = (a["primID"] == b["primID"]) & (near | ~hit)
        assert (~same).sum() <= EDGE_SHARE * len(same), (~same).sum()
    else:
        same = (a["primID"] == b["primID"]) & ((a["tfar"] == b["tfar"]) | ~hit)
        assert same.all()
    assert np.isinf(a["tfar"][(a["primID"] < 0)]).all()  # embreex's misses say 1e37
    return int(hit.sum())


def _as_embreex(levels):
    """How close to embreex's a scene's distances are (:func:`_same_hits`' ``within``)."""
    return DISTANCE_ROUNDING if levels else QUAD_ROUNDING


@pytest.fixture(params=["one level", "two levels"])
def levels(request, monkeypatch):
    """Scenes built one-level, or two-level (each part its own scene) whatever their size."""
    two = request.param == "two levels"
    monkeypatch.setattr(embree, "TWO_LEVEL_TRIANGLES", 0 if two else 1 << 62)
    return two


@pytest.mark.parametrize("stage", ["louvre.usda", "downlight.usda",
                                   "reference/integrating_sphere.usda",
                                   "reference/fresnel_slab.usda"])
def test_a_geometry_per_part_hits_what_embreex_hits(stage, levels):
    ps = prepare(read_stage(STAGES / stage))
    assert isinstance(ps.embree, embree.PartScene) and ps.embree.two_level == levels
    o, d = _traced_rays(ps)
    bare = embree_scene(_triangles(ps), (), parts=False)
    assert _same_hits(ps.intersect(o, d), bare.run(o, d, output=1),
                      _as_embreex(levels)) > 0.2 * len(o)


def test_an_edited_part_is_rebuilt_alone_and_hits_as_a_fresh_build(levels):
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
    assert updated.embree.moved == []  # its frame no longer places the new triangles
    fresh = prepare(moved, ps.frame)
    assert fresh.embree is not ps.embree and len(fresh.embree.rebuilt) > 1
    now = updated.intersect(o, d)
    _same_hits(now, fresh.intersect(o, d))  # the same structure: exactly
    _same_hits(now, embree_scene(_triangles(ps, moved), (), parts=False).run(o, d, output=1),
               _as_embreex(levels))
    assert (now["primID"] != before["primID"]).sum() > 100  # the blade moved in their way
    # unchanged triangles rebuild nothing; a new part layout is not an update
    assert prepare(moved, ps.frame, previous=updated).embree.rebuilt == []
    assert not ps.embree.update(_triangles(ps, moved), np.zeros(len(tri), np.int64))


def _moved_on_the_stage(tmp_path, part: str, by=(0.0, 2.0, 0.0)):
    """The louvre read again after one more translate op on ``part`` (stage units)."""
    from pxr import Gf, Usd, UsdGeom

    copy = tmp_path / "louvre.usda"
    copy.write_text((STAGES / "louvre.usda").read_text())
    stage = Usd.Stage.Open(str(copy))
    UsdGeom.Xformable(stage.GetPrimAtPath(part)).AddTranslateOp(
        opSuffix="moved").Set(Gf.Vec3d(*by))
    stage.Save()
    return read_stage(copy)


def test_a_part_moved_by_its_transform_is_placed_anew_not_rebuilt(tmp_path, levels):
    scene = read_stage(STAGES / "louvre.usda")
    ps = prepare(scene)
    o, d = _traced_rays(ps)
    before = ps.intersect(o, d)
    blade = int(np.argmax(np.bincount(scene.part_index)))
    moved = _moved_on_the_stage(tmp_path, scene.parts[blade])
    assert moved.parts == scene.parts and moved.part_frames[blade] is not None
    assert np.array_equal(moved.part_frames[blade].local, scene.part_frames[blade].local)
    updated = prepare(moved, ps.frame, previous=ps)
    assert updated.embree is ps.embree
    # two-level: the blade's transform alone changed, nothing is rebuilt
    assert (updated.embree.rebuilt, updated.embree.moved) == (
        ([], [blade]) if levels else ([blade], []))
    fresh = prepare(moved, ps.frame)
    now = updated.intersect(o, d)
    _same_hits(now, fresh.intersect(o, d))  # the same structure: exactly
    _same_hits(now, embree_scene(_triangles(ps, moved), (), parts=False).run(o, d, output=1),
               _as_embreex(levels))
    assert (now["primID"] != before["primID"]).sum() > 100  # the blade moved in their way
    # placed back where it was: the hits of the first build, exactly
    back = prepare(scene, ps.frame, previous=updated)
    assert back.embree.rebuilt == [] if levels else back.embree.rebuilt == [blade]
    _same_hits(back.intersect(o, d), before)


def test_two_levels_trace_what_one_level_traces_but_for_grazing_rays(monkeypatch):
    """A batch traced two-level: the same photons' counts as one level but for the rare
    photon a grazing ray sends elsewhere, and the same exactly when traced again."""
    scene = read_stage(STAGES / "louvre.usda")
    job = BatchJob(0, 0, 60000, 4, 16)
    tallies = []
    for threshold in (1 << 62, 0, 0):  # one level, then two, twice
        monkeypatch.setattr(embree, "TWO_LEVEL_TRIANGLES", threshold)
        ps = prepare(scene)
        assert ps.embree.two_level == (threshold == 0)
        tallies.append(trace_batch(ps, job, records=True))
    one, two, again = tallies
    assert np.array_equal(two.counts, again.counts) and np.array_equal(two.cells, again.cells)
    assert np.array_equal(two.records.texel, again.records.texel)
    moved = (one.records.texel != two.records.texel).sum()
    assert moved <= 20 * EDGE_SHARE * job.count, moved  # a photon's path, not one ray


def test_without_the_library_embreex_traces_the_same_photons(monkeypatch):
    """embreex's triangles trace the photons our quads trace: the same, but for the rare
    photon whose path a distance's last bits turn elsewhere."""
    scene = read_stage(STAGES / "downlight.usda")
    job = BatchJob(0, 0, 20000, 9, 16)
    ours = trace_batch(prepare(scene), job, records=True)
    monkeypatch.setattr(embree, "library", lambda: None)
    monkeypatch.setattr("lumitrace.trace.prepared.library", lambda: None)
    ps = prepare(scene)
    assert not isinstance(ps.embree, embree.PartScene)
    theirs = trace_batch(ps, job, records=True)
    other = ((ours.records.texel != theirs.records.texel)
             | (ours.records.segments != theirs.records.segments)
             | (ours.records.cells != theirs.records.cells).any(axis=-1)).sum()
    assert other <= 20 * EDGE_SHARE * job.count, other
    assert np.abs(ours.counts - theirs.counts).sum() <= 2 * other
    assert abs(ours.segments - theirs.segments) <= 20 * other


def test_quads_hold_every_triangle_once_as_embree_splits_them():
    """Triangles that follow one another and share an edge are one quad whose two
    triangles (Embree's (q0, q1, q3) and (q2, q3, q1)) are theirs; the rest stand alone
    as a quad with its last corner repeated."""
    rng = np.random.default_rng(3)
    p = rng.normal(size=(8, 3)).astype(np.float32)
    tri = p[[[0, 1, 2], [2, 1, 3],  # share 1-2: a quad
             [4, 5, 6],  # shares nothing with the next
             [0, 1, 7], [1, 7, 0],  # the same corners in another turn: not an edge alone
             [3, 4, 5], [5, 4, 6], [6, 4, 7]]]  # a run of three: the first two pair
    corners, held = embree.quads(tri)
    assert held.tolist() == [[0, 1], [2, 2], [3, 3], [4, 4], [5, 6], [7, 7]]
    for q, (i, j) in zip(corners, held):
        first, second = q[[0, 1, 3]], q[[2, 3, 1]]
        assert _turn_of(first, tri[i])  # the first triangle as given, in its own turn
        assert {tuple(c) for c in second} == {tuple(c) for c in tri[j]} if i != j \
            else (q[3] == q[2]).all()


def _turn_of(a, b) -> bool:
    """Whether triangle ``a``'s corners are ``b``'s in the same cyclic turn."""
    return any((np.roll(b, k, axis=0) == a).all() for k in range(3))


@pytest.mark.parametrize("name", ["downlight.usda", "louvre.usda"])
def test_the_reach_box_is_the_normalised_triangles_box_widened(name):
    """The box a ray must meet to be cast is the box of the traced (normalised) triangles,
    to the bit, widened by the margin: taken from the world bounds, not a normalised copy."""
    from lumitrace.scene import point_bounds
    from lumitrace.trace.prepared import REACH_MARGIN, normalised

    ps = prepare(read_stage(STAGES / name))
    tri = normalised(ps.scene, ps.center, ps.scale).reshape(-1, 3)
    margin = REACH_MARGIN * max(1.0, float(np.abs(tri).max()))
    lo, hi = ps.reach_box
    assert np.array_equal(lo, tri.min(axis=0) - margin)
    assert np.array_equal(hi, tri.max(axis=0) + margin)
    pts = np.random.default_rng(3).normal(size=(1001, 3)) * [1.0, 1e-3, 1e3]
    assert all(np.array_equal(a, b) for a, b in
               zip(point_bounds(pts), (pts.min(axis=0), pts.max(axis=0))))



_FIRST_DEVICES_AT_ONCE = """
import threading
from lumitrace.trace import embree

start = threading.Barrier(4)
got = []

def first():
    start.wait()  # four threads ask for the process's first Embree device at once
    got.append(embree._device())

threads = [threading.Thread(target=first) for _ in range(4)]
for t in threads:
    t.start()
for t in threads:
    t.join()
print(len(set(got)))
"""


def test_threads_making_their_first_scenes_at_once_share_one_device():
    """Threads of a fresh process (a Dask worker's first candidates) that build their
    scenes at once get the one device: with a device each, one device's geometry went into
    another's scene, and a candidate's counts mixed another's (1 in 2 runs of the Dask
    test)."""
    import subprocess
    import sys

    for _ in range(3):
        p = subprocess.run([sys.executable, "-c", _FIRST_DEVICES_AT_ONCE], capture_output=True,
                           text=True, timeout=120)
        assert p.returncode == 0, p.stderr[-3000:]
        assert p.stdout.split()[-1] == "1", p.stdout
