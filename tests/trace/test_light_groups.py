"""Many identical lights traced as one group (:mod:`lumitrace.scene.groups`): the stage
reader groups them, each light sends photons in proportion to its flux, the group's map
is the lights' map traced one by one (z-scores against it), and an edit that changes one
light's flux retraces the group to exactly what a fresh trace gives."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats
from stress_cases import add_disk_light, add_mesh, new_stage, square

from lumitrace.delta.effect import classify
from lumitrace.run.incremental import retrace, select
from lumitrace.run.session import Refinement, run
from lumitrace.run.settings import TraceSettings
from lumitrace.scene.groups import GROUP_MIN, group_emitters
from lumitrace.stage.reader import read_stage
from lumitrace.trace import rng
from lumitrace.trace.emission import emit, group_lights
from lumitrace.trace.prepared import TracingFrame, prepare
from lumitrace.trace.tracer import trace_batch

SIDE = 8  # an 8 x 8 board: 64 lights, the smallest group
#: the lights face away from their board: no photon comes back to it, as the run says
pytestmark = pytest.mark.filterwarnings("ignore:1 part.s. no traced photon reached")
PITCH = 0.01  # m


def _board(path, fluxes=None, radius=0.002):
    """``SIDE`` x ``SIDE`` disk lights facing down from a white board beside a mirror wall
    (lights near it send more light across: where a light sits changes the map)."""
    stage = new_stage(path)
    fluxes = np.full(SIDE * SIDE, 10.0) if fluxes is None else fluxes
    for k, f in enumerate(fluxes):
        i, j = divmod(k, SIDE)
        add_disk_light(stage, f"/Luminaire/Board/Led_{i}_{j}", radius, flux=float(f),
                       translate=((i - 3.5) * PITCH, (j - 3.5) * PITCH, -0.001))
    p, f = square(0.06, 0.0, up=False)
    add_mesh(stage, "/Luminaire/Board/Plate", p, f, 1.0, "diffuse", reflectance=0.8)
    wall = np.array([[0.045, -0.06, 0.0], [0.045, 0.06, 0.0], [0.045, 0.06, -0.05],
                     [0.045, -0.06, -0.05]])
    add_mesh(stage, "/Luminaire/Wall", wall, [[0, 1, 2, 3]], 1.0, "mirror",
             specularReflectance=0.9)
    stage.GetRootLayer().Save()
    return path


def _fluxes():
    return 1.0 + np.arange(SIDE * SIDE, dtype=np.float64)  # 1 .. 64 lm, all different


def test_the_reader_groups_identical_lights_only(tmp_path):
    scene = read_stage(_board(tmp_path / "b.usda", _fluxes()))
    (e,) = scene.emitters
    assert len(e.light_paths) == SIDE * SIDE == GROUP_MIN
    assert e.path == "/Luminaire/Board/Led_0_0[+63]" and e.flux == pytest.approx(2080.0)
    np.testing.assert_allclose(e.group.shares, _fluxes() / 2080.0)
    np.testing.assert_allclose(e.light_origins()[9], [(1 - 3.5) * PITCH, (1 - 3.5) * PITCH,
                                                      -0.001], atol=1e-12)
    # one light of another size stays itself; below GROUP_MIN nothing is grouped
    other = dataclasses.replace(e, path="/Other", radius=0.003, group=None)
    lights = [dataclasses.replace(e, path=p, group=None, flux=1.0) for p in e.light_paths]
    assert [x.path for x in group_emitters([other] + lights)] == ["/Other", e.path]
    assert len(group_emitters(lights[:-1])) == GROUP_MIN - 1
    # the box the goniophotometer counts in holds every light, not only the first
    hi = scene.shape_points().max(axis=0)
    assert hi[0] == pytest.approx(0.06) and hi[1] == pytest.approx(0.06)


def test_each_light_sends_photons_by_its_share_of_the_flux(tmp_path):
    scene = read_stage(_board(tmp_path / "b.usda", _fluxes()))
    (e,) = scene.emitters
    key = rng.stream_key(3, e.key)
    n = 400_000
    picked = group_lights(e, rng.photon_hash(key, np.arange(n, dtype=np.int64)))
    observed = np.bincount(picked, minlength=len(e.light_paths))
    assert stats.chisquare(observed, n * e.group.shares).pvalue > 1e-3
    # the photons start on their light's disk
    p, _ = emit(e, key, np.arange(2000, dtype=np.int64))
    centre = e.light_origins()[picked[:2000]]
    assert np.all(np.linalg.norm(p.T[:, :2] - centre[:, :2], axis=1) <= 0.002 + 1e-9)


def test_the_group_map_is_the_lights_map(tmp_path):
    """The group and its 64 lights traced one by one: the same texel fluxes within their
    errors (z-scores of mean 0 and unit variance) and the same flux escaped."""
    scene = read_stage(_board(tmp_path / "b.usda", _fluxes()))
    apart = dataclasses.replace(scene, emitters=tuple(
        dataclasses.replace(scene.emitters[0], path=p, flux=2080.0 * s, group=None,
                            to_world=_moved(scene.emitters[0].to_world, o))
        for p, o, s in zip(scene.emitters[0].light_paths, scene.emitters[0].group.offsets,
                           scene.emitters[0].group.shares)))
    settings = TraceSettings(photons=640_000, resolution=8, seed=5, threads=2)
    a = run(scene, settings).accumulator
    b = run(apart, settings).accumulator
    fa, fb = a.texel_flux().ravel(), b.texel_flux().ravel()
    var = a.flux_variance().ravel() + b.flux_variance().ravel()
    lit = var > 0
    z = (fa - fb)[lit] / np.sqrt(var[lit])
    assert lit.sum() > 100
    assert abs(z.mean()) < 4.0 / np.sqrt(lit.sum()) and 0.8 < z.var() < 1.25
    assert a.fluxes()["escaped"] == pytest.approx(b.fluxes()["escaped"], rel=0.01)


def _moved(m, offset):
    m = np.array(m, np.float64)
    m[:3, 3] += offset
    return m


def test_dimming_the_board_is_a_rescale_and_one_light_retraces_the_group(tmp_path):
    """Every light's flux halved keeps their shares: a rescale. Flux moved between two
    lights changes the shares: the group is retraced, and equals a fresh trace."""
    old = read_stage(_board(tmp_path / "a.usda", _fluxes()))
    dimmed = read_stage(_board(tmp_path / "b.usda", 0.5 * _fluxes()))
    assert classify(old, dimmed).kind == "flux"
    one = _fluxes()
    one[5], one[6] = 10.0, 3.0  # 6 and 7 lm before: the board's flux unchanged
    edited = read_stage(_board(tmp_path / "c.usda", one))
    assert classify(old, edited).kind == "emitter"
    # the edited group retraced from the records is a fresh trace of it, count for count
    settings = TraceSettings(photons=40_000, resolution=8, seed=2, threads=1,
                             batch_size=8192)
    frame = TracingFrame.of(old)
    r = Refinement(old, settings, records_cap=1 << 30)
    ps = prepare(old, frame)
    while jobs := r.next_jobs():
        r.add_round([trace_batch(ps, j, records=True) for j in jobs])
    sel = select(r.records, r.scene, edited, frame)
    assert sel.restart is None and sel.photons == r.accumulator.photons
    ps = prepare(edited, frame, previous=ps)
    retrace(r, edited, sel, lambda work: [trace_batch(ps, j, photons=ids, records=True)
                                          for j, ids in work], 8192)
    fresh = run(edited, settings, frame=frame)
    assert np.array_equal(r.accumulator.counts(), fresh.accumulator.counts())
    assert np.array_equal(r.accumulator.emitters[0].cells, fresh.accumulator.emitters[0].cells)


def test_the_photometric_variant_turns_every_light_of_the_group_off(tmp_path):
    import subprocess
    import sys

    from pxr import Usd

    stage_path = _board(tmp_path / "b.usda", _fluxes())
    p = subprocess.run([sys.executable, "-m", "lumitrace", "trace", str(stage_path),
                        "--photons", "20000", "--resolution", "8", "--no-pictures",
                        "--no-progress"], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    stage = Usd.Stage.Open(str(stage_path))
    vset = stage.GetPrimAtPath("/Luminaire").GetVariantSet("lumitraceRepresentation")
    leds = [f"/Luminaire/Board/Led_{i}_{j}" for i in range(SIDE) for j in range(SIDE)]
    assert all(stage.GetPrimAtPath(x).IsActive() for x in leds)
    vset.SetVariantSelection("photometric")
    assert not any(stage.GetPrimAtPath(x).IsActive() for x in leds)
    assert stage.GetPrimAtPath("/Luminaire/lumitracePhotometricLight").IsActive()
