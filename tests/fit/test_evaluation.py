"""A candidate's merit does not depend on how it was traced: selectively from a base trace
(only the photons its edit can change, the rest kept), afresh, on threads, on worker
processes or on a Dask cluster, its counts are the same, count for count. And the merit's
standard error and the comparison noise say what they claim: over seeds, the spread of a
merit is its stated error, and the spread of a difference between neighbours (common random
numbers) the comparison noise the halves measure, far below it."""
from __future__ import annotations


import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom

from helpers.fit_stages import mirror_cup

from lumitrace.fit.candidates import CandidateStage
from lumitrace.fit.measure import Plan, make_base, measurement, retrace_counts, trace_counts
from lumitrace.fit.objective import Needs, Objective
from lumitrace.fit.parameters import resolve
from lumitrace.fit.pool import Evaluator
from lumitrace.fit.search import Evaluation, comparison_noise
from lumitrace.fit.target import read_target

BAFFLE = "/Luminaire/Baffle.xformOp:translate[0]=0.02:0.05"
NEEDS = Needs("rotational", tuple(np.arange(0.0, 180.1, 2.5)), ())


@pytest.fixture(scope="module")
def baffled(tmp_path_factory):
    """The mirror cup with a small cube below it, off the axis: moving the cube changes
    the paths of a few of the photons (those that pass near it)."""
    path = mirror_cup(tmp_path_factory.mktemp("baffle") / "cup.usda")
    stage = Usd.Stage.Open(str(path))
    cube = UsdGeom.Cube.Define(stage, "/Luminaire/Baffle")
    cube.CreateSizeAttr(0.004)
    cube.AddTranslateOp().Set(Gf.Vec3d(0.03, 0.0, -0.06))
    stage.GetRootLayer().Save()
    cs = CandidateStage(path)
    params = resolve(cs.stage, [BAFFLE])
    return cs, params, Plan.of(cs.scene(params, [0.03]), seed=3)


def _same_counts(a, b) -> None:
    for x, y in zip(a.emitters, b.emitters):
        assert x.photons == y.photons
        np.testing.assert_array_equal(x.counts, y.counts)
        np.testing.assert_array_equal(x.cells, y.cells)
        assert (x.absorbed, x.cut, x.segments) == (y.absorbed, y.cut, y.segments)


def test_a_selective_retrace_gives_a_fresh_traces_counts(baffled):
    cs, params, plan = baffled
    base = make_base(cs.scene(params, [0.03]), plan, 1 << 16)
    scene = cs.scene(params, [0.026])
    got = retrace_counts(base, scene, plan)
    assert got is not None
    acc, retraced = got
    assert 0 < retraced < 0.5 * (1 << 16)  # a few photons traced again, not all
    fresh, _ = trace_counts(scene, plan, 1 << 16)
    _same_counts(acc, fresh)
    # the cube moved out of the box the records' grid covers: traced afresh
    assert retrace_counts(base, cs.scene(params, [0.045]), plan) is None


@pytest.mark.parametrize("mode", ["threads", "processes"])
def test_threads_and_processes_give_the_same_measurements(baffled, mode):
    cs, params, plan = baffled
    scenes = [cs.scene(params, [x]) for x in (0.022, 0.026, 0.03, 0.045)]
    want = [measurement(s, trace_counts(s, plan, 1 << 15)[0], NEEDS) for s in scenes]
    ev = Evaluator(plan, NEEDS, mode, workers=2)
    ev.use_base(scenes[2])
    try:
        got = ev.evaluate(scenes, 1 << 15)
    finally:
        ev.close()
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g.measurement.candela, w.candela)
        np.testing.assert_array_equal(g.measurement.sigma, w.sigma)
    if mode == "threads":  # the cube's moves near the base were retraced selectively
        assert got[1].retraced is not None and got[3].retraced is None


def test_a_dask_cluster_gives_the_same_measurements(baffled):
    distributed = pytest.importorskip("distributed")
    cs, params, plan = baffled
    scenes = [cs.scene(params, [x]) for x in (0.022, 0.04)]
    want = [measurement(s, trace_counts(s, plan, 1 << 15)[0], NEEDS) for s in scenes]
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=True,
                                  host="127.0.0.1", dashboard_address=":0") as c:
        ev = Evaluator(plan, NEEDS, "dask", scheduler=c.scheduler_address)
        try:
            got = ev.evaluate(scenes, 1 << 15)
        finally:
            ev.close()
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g.measurement.candela, w.candela)


def test_merit_errors_and_comparison_noise_are_what_they_say(tmp_path):
    """Over 24 seeds of two neighbouring candidates (mirror reflectances 0.93 and 0.95
    against the cup traced at 0.95): the spread of each merit is its stated standard
    error (within the sampling error of 24 draws; measured 0.87 and 0.95 of it), and the
    spread of their difference is about the comparison noise the halves estimate (1.42
    of it: near the noise floor the merit is not linear in the noise, and the halves'
    floor is higher) and less than half of either merit's own error."""
    from lumitrace.publish.outputs import write_outputs
    from lumitrace.run.session import run
    from lumitrace.run.settings import TraceSettings
    from lumitrace.stage.reader import read_stage

    true = mirror_cup(tmp_path / "true.usda")
    target = write_outputs(run(read_stage(true), TraceSettings(photons=400_000, seed=99,
                                                               threads=2)),
                           tmp_path / "t", sublayer=False, pictures=False)["ldt"]
    objective = Objective(read_target(target))
    cs = CandidateStage(mirror_cup(tmp_path / "cup.usda", 0.9))
    params = resolve(cs.stage, ["/Luminaire/Materials/Mirror.lumitrace:specularReflectance"])
    scenes = [cs.scene(params, [v]) for v in (0.93, 0.95)]
    merits, errors, noise = [], [], []
    for seed in range(24):
        plan = Plan.of(scenes[0], seed)
        ms = [objective.merit(measurement(s, trace_counts(s, plan, 1 << 14)[0],
                                          objective.needs)) for s in scenes]
        merits.append([m.merit for m in ms])
        errors.append([m.error for m in ms])
        evs = [Evaluation(i, 0, (), 0, m.merit, m.error, m.noise, m.match, (), True, None,
                          0, 0, halves=m.halves) for i, m in enumerate(ms)]
        noise.append(comparison_noise(evs))
    merits, errors = np.array(merits), np.array(errors)
    spread = merits.std(axis=0, ddof=1)
    stated = np.sqrt((errors ** 2).mean(axis=0))
    # 24 draws: the sample standard deviation is within about +-30% (2 sigma) of the truth
    np.testing.assert_array_less(spread, 1.35 * stated)
    np.testing.assert_array_less(0.65 * stated, spread)
    diff = (merits[:, 0] - merits[:, 1]).std(ddof=1)
    # the noise of a difference of two: twice a generation's comparison noise variance
    assert 0.6 < diff / (np.sqrt(2.0) * np.sqrt(np.mean(np.square(noise)))) < 1.6
    assert diff < 0.5 * stated.min()  # common random numbers: most noise cancels
