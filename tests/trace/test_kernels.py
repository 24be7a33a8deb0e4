"""The compiled photon kernels against independent numpy definitions: the same random
numbers, the same cube-map texels as ImfEnvmap's layout, the goniophotometer's cells and
exit bins by their definitions, and photon paths that do not depend on the wave."""
import numpy as np
import pytest

from lumitrace.film import cubemap
from lumitrace.film import goniometer as gm
from lumitrace.scene import Emitter
from lumitrace.trace import kernels, rng
from lumitrace.trace.emission import emit
from lumitrace.trace.tracer import _CUBE_LAYOUT


def _directions(n, seed=0):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    axes = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 1, 1], [-1, 1, -1],
                     [0, -1, 1], [0.0, 0, -1]])
    return np.vstack([d, axes / np.linalg.norm(axes, axis=1, keepdims=True), -axes])


def test_random_numbers_are_the_counter_based_stream():
    key = rng.stream_key(5, 77)
    idx = np.arange(2000, dtype=np.int64)
    want = rng.uniforms(key, idx, 12, 4)
    base = rng.photon_hash(key, idx)
    for i in range(0, 2000, 97):
        a = kernels._uniform_pair(base[i], 12)
        b = kernels._uniform_pair(base[i], 13)
        assert (a[0], a[1], b[0], b[1]) == tuple(w[i] for w in want)


def test_emitted_hashes_are_the_photon_hashes():
    e = Emitter(path="/L", kind="disk", flux=1.0, to_world=np.eye(4), radius=0.1)
    key = rng.stream_key(3, e.key)
    idx = np.arange(100, 300, dtype=np.int64)
    out = (np.empty((3, 200)), np.empty((3, 200)), np.empty((3, 200)), np.empty(200, np.uint64))
    emit(e, key, idx, normals=True, out=out)
    assert np.array_equal(out[3], rng.photon_hash(key, idx))


@pytest.mark.parametrize("res", [1, 2, 7, 32])
def test_texels_are_imfenvmaps(res):
    d = _directions(20_000, seed=res)
    # directions exactly on pixel positions and on the faces' edges and corners
    edge = cubemap.texel_directions(res).reshape(-1, 3)
    d = np.vstack([d, edge, [[0.0, 0.0, 0.0]]])
    assert np.array_equal(kernels.texels(np.ascontiguousarray(d.T), res, _CUBE_LAYOUT),
                          cubemap.texel_index(d, res))


def _frame_axes(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


@pytest.mark.parametrize("seed", [0, 1])
def test_goniometer_cells_follow_their_edges(seed):
    axes = _frame_axes(seed) if seed else np.eye(3)
    r = np.random.default_rng(seed)
    c = r.uniform(0, 360, 50_000)
    g = np.degrees(np.arccos(r.uniform(-1, 1, 50_000)))
    g = np.concatenate([g, [0.1, 179.9, 41.4, 41.5, 60.2, 75.5, 75.6]])
    c = np.concatenate([c, [0.6, 359.4, 1.3, 181.0, 90.1, 270.2, 44.9]])
    local = np.stack([np.sin(np.radians(g)) * np.cos(np.radians(c)),
                      np.sin(np.radians(g)) * np.sin(np.radians(c)), -np.cos(np.radians(g))])
    d = np.ascontiguousarray(axes.T @ local)
    cell, _ = kernels.gonio_bins(np.zeros_like(d), d, np.ascontiguousarray(axes),
                                 np.full(3, -1.0), np.ones(3), gm.EXTRA_EDGES, gm.C_STEP,
                                 gm.GAMMA_STEP, gm.N_C, gm.N_GAMMA, gm.EXIT_SIDE)
    want = (np.floor(c / gm.C_STEP).astype(int) * gm.N_GAMMA
            + np.searchsorted(gm.GAMMA_EDGES, g, side="right") - 1)
    # away from the edges (float rounding decides exactly on one), every photon is in its cell
    ce = np.abs(c / gm.C_STEP - np.round(c / gm.C_STEP)) > 1e-7
    ge = np.min(np.abs(g[:, None] - gm.GAMMA_EDGES[None]), axis=1) > 1e-7
    clear = ce & ge
    assert clear.sum() > 49_000
    assert np.array_equal(cell[clear], want[clear])


def test_fast_cells_are_the_exact_cells_even_a_hair_from_an_edge():
    """Cells come from fast angles unless those are within a margin of an edge; the result
    is then libm's own, so even directions 1e-9 deg off an edge land where acos and atan2
    put them."""
    r = np.random.default_rng(3)
    k = r.integers(0, len(gm.GAMMA_EDGES), 4000)
    j = r.integers(0, gm.N_C, 4000)
    off = r.choice([-1e-9, 0.0, 1e-9, -1e-6, 1e-6, 3e-5], 4000)
    g = np.clip(gm.GAMMA_EDGES[k] + off, 0.0, 180.0)
    c = j * gm.C_STEP + r.choice([-1e-9, 0.0, 1e-9, 2e-6], 4000)
    g = np.concatenate([g, np.degrees(np.arccos(r.uniform(-1, 1, 4000)))])
    c = np.concatenate([c, r.uniform(0, 360, 4000)])
    d = np.stack([np.sin(np.radians(g)) * np.cos(np.radians(c)),
                  np.sin(np.radians(g)) * np.sin(np.radians(c)), -np.cos(np.radians(g))])
    args = (gm.EXTRA_EDGES, 1.0 / gm.C_STEP, 1.0 / gm.GAMMA_STEP, gm.N_C, gm.N_GAMMA)
    cell, _ = kernels.gonio_bins(np.zeros_like(d), np.ascontiguousarray(d), np.eye(3),
                                 np.full(3, -1.0), np.ones(3), gm.EXTRA_EDGES, gm.C_STEP,
                                 gm.GAMMA_STEP, gm.N_C, gm.N_GAMMA, gm.EXIT_SIDE)
    exact = [kernels._gonio_cell_exact(*d[:, i], *args) for i in range(d.shape[1])]
    assert np.array_equal(cell, exact)
    # and the fast angles are as close as the margin assumes
    x = np.linspace(-1.0, 1.0, 200_001)
    assert max(abs(kernels._acos_fast(v) - np.arccos(v)) for v in x[::50]) < 2.5e-8
    a = np.linspace(0, 2 * np.pi, 40_001)
    assert max(abs(kernels._atan2_fast(np.sin(t), np.cos(t)) - np.arctan2(np.sin(t), np.cos(t)))
               for t in a[:-1]) < 1.5e-8


def test_directions_exactly_on_c_axes_and_diagonals_take_the_cell_above():
    """As atan2 puts them: C = 0, 45, ..., 315 deg exactly start their cells."""
    s, z = 0.6, -0.8  # gamma = acos(0.8), well inside its gamma cell
    h = s / np.sqrt(2.0)
    local = np.array([[s, 0, z], [h, h, z], [0, s, z], [-h, h, z], [-s, 0, z], [-h, -h, z],
                      [0, -s, z], [h, -h, z]]).T
    cell, _ = kernels.gonio_bins(np.zeros_like(local), np.ascontiguousarray(local), np.eye(3),
                                 np.full(3, -1.0), np.ones(3), gm.EXTRA_EDGES, gm.C_STEP,
                                 gm.GAMMA_STEP, gm.N_C, gm.N_GAMMA, gm.EXIT_SIDE)
    g = np.searchsorted(gm.GAMMA_EDGES, np.degrees(np.arccos(0.8)), side="right") - 1
    c = np.arange(8) * int(round(45.0 / gm.C_STEP))
    assert np.array_equal(cell, c * gm.N_GAMMA + g)


def _exits_by_definition(p, d, lo, hi):
    """Exit bins of rays from p along d (N, 3, photometric axes = world) from the box."""
    with np.errstate(divide="ignore"):
        t = np.where(d > 0, (hi - p) / d, np.where(d < 0, (lo - p) / d, np.inf))
    axis = np.argmin(t, axis=1)
    n = np.arange(len(p))
    q = p + np.maximum(t[n, axis], 0)[:, None] * d
    u = (np.clip(q, lo, hi) - lo) / (hi - lo)
    face = np.array([2, 4, 0])[axis] + (d[n, axis] > 0)
    ua = np.array([1, 0, 0])[axis]
    va = np.array([2, 2, 1])[axis]
    col = np.minimum((u[n, ua] * gm.EXIT_SIDE).astype(int), gm.EXIT_SIDE - 1)
    row = np.minimum((u[n, va] * gm.EXIT_SIDE).astype(int), gm.EXIT_SIDE - 1)
    return gm.N_CELLS + (face * gm.EXIT_SIDE + row) * gm.EXIT_SIDE + col


def test_exit_bins_follow_their_faces():
    lo, hi = np.array([-0.2, -0.1, -0.05]), np.array([0.3, 0.1, 0.02])
    r = np.random.default_rng(4)
    p = r.uniform(lo, hi, size=(20_000, 3))
    d = _directions(20_000 - 16, seed=4)
    args = (np.eye(3), lo, hi, gm.EXTRA_EDGES, gm.C_STEP, gm.GAMMA_STEP, gm.N_C, gm.N_GAMMA,
            gm.EXIT_SIDE)
    _, ex = kernels.gonio_bins(np.ascontiguousarray(p.T), np.ascontiguousarray(d.T), *args)
    assert np.array_equal(ex, _exits_by_definition(p, d, lo, hi))
    # straight down from the centre: the middle of the bottom face (face 0)
    _, ex = kernels.gonio_bins(np.zeros((3, 1)), np.array([[0.0], [0.0], [-1.0]]), *args)
    b = ex[0] - gm.N_CELLS
    assert b // gm.EXIT_SIDE**2 == gm.FACES.index("bottom")
    col, row = b % gm.EXIT_SIDE, (b // gm.EXIT_SIDE) % gm.EXIT_SIDE
    assert (col, row) == (int(0.4 * gm.EXIT_SIDE), int(0.5 * gm.EXIT_SIDE))


def test_a_batchs_escapes_are_binned_as_each_direction_is():
    """The tracer bins escapes in vectorised chunks: the counts of a batch (a few chunks
    and a part one) are those of its escapes binned one by one, half by half."""
    from lumitrace.film.accumulate import counts_of
    from lumitrace.scene import Scene
    from lumitrace.trace import tracer
    from lumitrace.trace.job import BatchJob
    from lumitrace.trace.prepared import prepare

    e = Emitter(path="/L", kind="sphere", flux=1.0, to_world=np.eye(4), radius=0.01)
    scene = Scene(np.zeros((0, 3, 3)), np.zeros(0, np.int32), np.zeros(0, np.int32), (), (),
                  (e,))
    ps, job = prepare(scene), BatchJob(0, 100, 3 * kernels._CHUNK + 77, 9, 16)
    t = tracer.trace_batch(ps, job, exit_rays=True)
    pos, d = t.exit_rays
    assert len(d) == job.count
    half = (rng.photon_hash(rng.stream_key(job.seed, e.key),
                            np.arange(job.first, job.stop)) & 1).astype(np.int64)
    tex = kernels.texels(np.ascontiguousarray(d.T), job.resolution, _CUBE_LAYOUT)
    assert np.array_equal(t.counts, counts_of(tex + half * t.counts.shape[1],
                                              t.counts.shape[1]))
    _, _, axes, lo, hi, *gonio, _ = ps.gonio_args
    cell, ex = kernels.gonio_bins(np.ascontiguousarray(pos.T), np.ascontiguousarray(d.T), axes,
                                  lo, hi, *gonio)
    want = counts_of(np.concatenate([cell, ex]) + gm.N_BINS * np.tile(half, 2), gm.N_BINS)
    dense = lambda c: c.dense() if hasattr(c, "dense") else c  # noqa: E731
    assert np.array_equal(dense(t.cells), dense(want))


def test_photons_that_cannot_meet_the_geometry_skip_embree_with_the_same_result(monkeypatch):
    """A light below a plate, facing away from it: no emitted photon can meet a triangle,
    none goes to Embree, and the tally is the one every photon cast through Embree gives."""
    from lumitrace.scene import Material, Scene
    from lumitrace.trace import tracer
    from lumitrace.trace.job import BatchJob
    from lumitrace.trace.prepared import prepare

    tri = np.array([[[-1.0, -1.0, 0.2], [1.0, -1.0, 0.2], [1.0, 1.0, 0.2]],
                    [[-1.0, -1.0, 0.2], [1.0, 1.0, 0.2], [-1.0, 1.0, 0.2]]])
    e = Emitter(path="/L", kind="disk", flux=1.0, to_world=np.eye(4), radius=0.1)
    scene = Scene(tri, np.zeros(2, np.int32), np.zeros(2, np.int32),
                  (Material("/M", "diffuse", reflectance=0.5),), ("/P",), (e,))
    job = BatchJob(0, 0, 5000, 3, 8)
    ps = prepare(scene)
    calls = []
    monkeypatch.setattr(ps, "intersect", lambda o, d: calls.append(len(o)))
    culled = tracer.trace_batch(ps, job, records=True)
    assert calls == [] and culled.escaped == 5000
    monkeypatch.undo()
    monkeypatch.setattr(kernels, "cull", lambda n, *a: n)  # every ray to Embree
    every = tracer.trace_batch(prepare(scene), job, records=True)
    assert np.array_equal(culled.counts, every.counts)
    dense = lambda c: c.dense() if hasattr(c, "dense") else c  # noqa: E731
    assert np.array_equal(dense(culled.cells), dense(every.cells))
    for a, b in zip(culled.records._arrays(), every.records._arrays()):
        assert np.array_equal(a, b)


def test_the_turn_is_cos_and_sin_of_the_angle_to_1e15():
    """The sampling's cos and sin of 2 pi u (polynomials, not libm): within 1e-15 over
    random 32-bit uniforms and every 1/4096 turn, exact at the quarter turns, and a unit
    vector to rounding."""
    u = np.concatenate([np.random.default_rng(5).integers(0, 2**32, 50_000) * 2.0**-32,
                        np.arange(4096) / 4096.0, [1.0 - 2.0**-32]])
    cs = np.array([kernels._turn(v) for v in u])
    a = 2.0 * np.pi * u
    assert np.abs(cs[:, 0] - np.cos(a)).max() < 1e-15
    assert np.abs(cs[:, 1] - np.sin(a)).max() < 1e-15
    assert np.abs(np.hypot(cs[:, 0], cs[:, 1]) - 1.0).max() < 4e-16
    assert [kernels._turn(q) for q in (0.0, 0.25, 0.5, 0.75)] == [
        (1.0, 0.0), (-0.0, 1.0), (-1.0, -0.0), (0.0, -1.0)]
