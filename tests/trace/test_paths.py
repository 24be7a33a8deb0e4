"""Whole photon paths in one compiled call against a bounce at a time: a photon draws the
same numbers either way, so every tally, record and exit ray is the same, bit for bit; and
so whatever the chunks a batch's paths are emitted and followed in."""
from pathlib import Path

import numpy as np
import pytest

from helpers.tallies import same_tally
from lumitrace.stage.reader import read_stage
from lumitrace.trace import embree
from lumitrace.trace.job import BatchJob
from lumitrace.trace.prepared import prepare
from lumitrace.trace.tracer import trace_batch

STAGES = Path(__file__).resolve().parents[2] / "stages"


def _same_as_waves(ps, job, **kw):
    """The deep trace of ``job``, checked against the same job a bounce at a time (as
    the benchmark traces it, keeping every ray)."""
    deep = trace_batch(ps, job, **kw)
    waves = trace_batch(ps, job, record_rays=True, **kw)
    assert deep.rays is None and len(waves.rays) >= 1
    assert deep.segments >= sum(len(o) for o, _ in waves.rays)
    waves.rays = None
    same_tally(deep, waves)
    return deep


@pytest.mark.skipif(embree.library() is None, reason="Embree's C API is not found here")
@pytest.mark.parametrize("stage", ["downlight.usda", "warm_downlight.usda", "louvre.usda",
                                   "reference/fresnel_slab.usda",
                                   "reference/integrating_sphere.usda",
                                   "reference/mirror_cup.usda"])
def test_whole_paths_tally_what_a_bounce_at_a_time_tallies(stage):
    scene = read_stage(STAGES / stage)
    ps = prepare(scene)
    assert ps.hit_args is not None  # traced deep
    for e in range(len(scene.emitters)):
        job = BatchJob(e, 5000, 4000, 3, 16)
        plain = _same_as_waves(ps, job)
        full = _same_as_waves(ps, job, records=True, exit_rays=True)
        assert full.segments == plain.segments and full.escaped == plain.escaped
        assert plain.escaped > 1000 and plain.part_hits.sum() > 1000


def test_a_scene_without_geometry_is_traced_deep_without_embree():
    ps = prepare(read_stage(STAGES / "reference" / "isotropic.usda"))
    assert ps.embree is None and ps.hit_args is not None
    t = _same_as_waves(ps, BatchJob(0, 0, 3000, 1, 16), records=True, exit_rays=True)
    assert t.escaped == t.photons == t.segments == 3000


def test_photons_cut_by_the_depth_limit_are_counted_alike():
    ps = prepare(read_stage(STAGES / "reference" / "integrating_sphere.usda"))
    t = _same_as_waves(ps, BatchJob(0, 0, 3000, 1, 16, max_depth=2), records=True)
    assert t.cut > 100 and t.cut + t.absorbed + t.escaped == t.photons


@pytest.mark.skipif(embree.library() is None, reason="Embree's C API is not found here")
@pytest.mark.parametrize("stage", ["warm_downlight.usda", "reference/mirror_cup.usda"])
def test_paths_followed_a_chunk_at_a_time_tally_what_one_chunk_tallies(stage, monkeypatch):
    """A batch's paths emitted and followed in chunks (of 999 photons, so the lanes' last
    packets of a chunk are part-filled), with records, exit rays and a spectral throughput:
    every tally the same as in one chunk, and as a bounce at a time."""
    from lumitrace.trace import tracer

    ps = prepare(read_stage(STAGES / stage))
    job = BatchJob(0, 1000, 4000, 3, 16)
    whole = trace_batch(ps, job, records=True, exit_rays=True)
    monkeypatch.setattr(tracer, "PATH_CHUNK", 999)
    chunked = _same_as_waves(ps, job, records=True, exit_rays=True)
    same_tally(chunked, whole)
    assert chunked.escaped > 1000


def test_a_ray_file_lights_photons_keep_their_bands_when_culled(tmp_path, monkeypatch):
    """Rays with wavelengths over a white floor that only some of them meet: the waves
    reorder the photons the floor cannot catch, whole paths do not; each photon starts
    in its own ray's band either way."""
    from pxr import Sdf, UsdLux

    from helpers.stages import add_mesh, new_stage, read
    from lumitrace import tm25

    n = 2000
    r = np.random.default_rng(4)
    dirs = r.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    wl = r.choice([450.0, 530.0, 610.0], n).astype(np.float32)
    rays = tm25.RayFile(positions=np.zeros((n, 3), np.float32),
                        directions=dirs.astype(np.float32),
                        flux=np.full(n, 0.5, np.float32), wavelengths=wl,
                        radiant=np.full(n, 1e-3, np.float32))
    (tmp_path / "rgb.TM25RAY").write_bytes(tm25.format_tm25(rays))
    stage = new_stage(tmp_path)
    add_mesh(stage, "/Luminaire/Floor", points=[(-1, -1, -0.5), (1, -1, -0.5), (1, 1, -0.5),
                                               (-1, 1, -0.5)])
    light = UsdLux.SphereLight.Define(stage, "/Luminaire/Rays").GetPrim()
    light.AddAppliedSchema("LumitraceEmitterAPI")
    light.CreateAttribute("lumitrace:rayFile", Sdf.ValueTypeNames.Asset).Set(
        Sdf.AssetPath("./rgb.TM25RAY"))
    scene = read(stage)
    assert scene.emitters[0].ray_bands and scene.colour == "spectral"
    ps = prepare(scene)
    t = _same_as_waves(ps, BatchJob(0, 0, 3000, 2, 8), records=True, exit_rays=True)
    assert 500 < t.part_hits.sum() < 2500  # some meet the floor, some cannot
    # in chunks, each photon's band drawn from its own hash all the same
    monkeypatch.setattr("lumitrace.trace.tracer.PATH_CHUNK", 700)
    same_tally(trace_batch(ps, BatchJob(0, 0, 3000, 2, 8), records=True, exit_rays=True), t)


def _lines(start: int, stop: int) -> range:
    """The 64-byte cache lines bytes ``start`` .. ``stop - 1`` lie on."""
    return range(start // 64, (stop - 1) // 64 + 1)


def test_the_counts_a_hit_adds_to_and_embrees_ray_share_no_cache_line():
    """Two tracing threads each write a part-hit count at every hit and a packet of rays
    (RTCRayHit4) at every Embree call: each sits on cache lines that hold nothing but its
    own buffer, so the two threads' small allocations never share a line (a shared one
    cost 10% more CPU)."""
    from lumitrace.trace.kernels.paths import _LANES, _PACKET_WORDS, _packet

    ps = prepare(read_stage(STAGES / "reference/mirror_cup.usda"))
    hits = trace_batch(ps, BatchJob(0, 0, 2000, 0, 16)).part_hits
    assert hits.sum() > 0
    whole = hits.base
    first, last = hits.ctypes.data, hits.ctypes.data + hits.nbytes
    # the lines the counts lie on start and end within their own allocation
    assert min(_lines(first, last)) * 64 >= whole.ctypes.data
    assert (max(_lines(first, last)) + 1) * 64 <= whole.ctypes.data + whole.nbytes
    for _ in range(4):  # wherever the allocation lands
        # the packet's valid mask on a line of its own, its RTCRayHit4 (20 rows of _LANES
        # words) on the lines after it, up to the end of the last
        buf = np.empty(_PACKET_WORDS, np.uint32)
        f, u, valid, packet = _packet(buf)
        assert valid % 64 == 0 and valid > buf.ctypes.data and packet == valid + 64
        assert u.ctypes.data == f.ctypes.data == valid
        assert packet + -(-20 * 4 * _LANES // 64) * 64 <= buf.ctypes.data + buf.nbytes


def test_a_new_packet_has_no_valid_ray_whatever_its_buffer_held():
    """A deep bounce casts only the lanes it fills: a lane left from the buffer's old bytes
    would send Embree a ray of garbage and hand back a hit on no triangle of ours."""
    from lumitrace.trace.kernels.paths import _LANES, _PACKET_WORDS, _packet

    buf = np.full(_PACKET_WORDS, 0xFFFFFFFF, np.uint32)
    f, u, valid, packet = _packet(buf)
    assert not u[:_LANES].any()
    assert np.all(u[_LANES:] == 0xFFFFFFFF)  # the rest is written ray by ray
