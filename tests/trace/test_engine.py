"""Engine guarantees: determinism, exact bookkeeping, flux conservation, unit invariance."""
from __future__ import annotations


import numpy as np
import pytest
from pxr import Usd, UsdGeom

from lumitrace.film.cubemap import texel_solid_angles
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage
from helpers.paths import ROOT

DOWNLIGHT = ROOT / "stages" / "downlight.usda"


@pytest.fixture(scope="module")
def downlight():
    return read_stage(DOWNLIGHT)


def _run(scene, progress=None, **kw):
    settings = dict(photons=300_000, resolution=32, seed=7, threads=2)
    settings.update(kw)
    return run(scene, TraceSettings(**settings), progress=progress)


def test_same_seed_gives_a_bit_identical_map_for_any_thread_count(downlight):
    a = _run(downlight, threads=1, batch_size=1 << 14).accumulator
    b = _run(downlight, threads=2, batch_size=1 << 17).accumulator
    assert np.array_equal(a.counts(), b.counts())
    assert np.array_equal(a.intensity(), b.intensity())
    assert [t.absorbed for t in a.emitters] == [t.absorbed for t in b.emitters]
    assert a.segments == b.segments
    c = _run(downlight, seed=8).accumulator
    assert not np.array_equal(a.counts(), c.counts())


def test_every_photon_is_accounted_for(downlight):
    acc = _run(downlight).accumulator
    for t in acc.emitters:
        assert t.escaped + t.absorbed + t.cut == t.photons
    f = acc.fluxes()
    assert f["escaped"] + f["absorbed"] + f["cut"] == pytest.approx(f["emitted"], rel=1e-9)
    assert f["emitted"] == pytest.approx(1200.0, rel=1e-12)
    assert 0.3 < f["escaped"] / f["emitted"] < 0.95  # a real downlight loses some light


def test_intensity_integrates_to_escaped_flux(downlight):
    acc = _run(downlight).accumulator
    integral = (acc.intensity() * texel_solid_angles(acc.resolution)).sum()
    assert integral == pytest.approx(acc.fluxes()["escaped"], rel=1e-12)


def test_photon_budget_is_exact_and_split_by_flux(downlight):
    res = _run(downlight, photons=123_457)
    assert res.accumulator.photons == 123_457


def test_depth_limit_cuts_and_reports(downlight):
    acc = _run(downlight, photons=50_000, max_depth=1).accumulator
    f = acc.fluxes()
    assert f["cut"] > 0
    assert f["escaped"] + f["absorbed"] + f["cut"] == pytest.approx(f["emitted"], rel=1e-9)


def test_millimetres_and_metres_give_the_same_map(tmp_path):
    """The downlight (modelled in mm) referenced into a metre stage scaled by 1/1000."""
    metre = tmp_path / "downlight_m.usda"
    stage = Usd.Stage.CreateNew(str(metre))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    root.AddScaleOp(UsdGeom.XformOp.PrecisionDouble).Set((0.001, 0.001, 0.001))
    root.GetPrim().GetReferences().AddReference(str(DOWNLIGHT), "/Luminaire")
    stage.SetDefaultPrim(root.GetPrim())
    stage.Save()
    mm_scene, m_scene = read_stage(DOWNLIGHT), read_stage(metre)
    assert m_scene.meters_per_unit == 1.0 and mm_scene.meters_per_unit == 0.001
    np.testing.assert_allclose(m_scene.triangles, mm_scene.triangles, rtol=0, atol=1e-15)
    n = 300_000
    a = _run(mm_scene, photons=n).accumulator
    b = _run(m_scene, photons=n).accumulator
    # the same photons: at most a handful take another path through float rounding
    moved = np.abs(a.counts() - b.counts()).sum()
    assert moved <= 1e-4 * n
    assert abs(a.fluxes()["escaped"] - b.fluxes()["escaped"]) <= 1e-4 * 1200


def test_worker_processes_give_the_same_map_as_threads(downlight):
    a = _run(downlight, photons=200_000, workers="threads").accumulator
    b = _run(downlight, photons=200_000, workers="processes").accumulator
    assert np.array_equal(a.counts(), b.counts())
    assert [t.absorbed for t in a.emitters] == [t.absorbed for t in b.emitters]


def test_rounds_grow_while_estimating_would_dominate(downlight, monkeypatch):
    """Once the rounds are full ones, they double while the map's estimate costs more than a
    tenth of tracing a round; how the photons are split into rounds changes nothing."""
    from lumitrace.run import session

    shown = []  # progress watched: every round is estimated
    monkeypatch.setattr(session, "ESTIMATE_SHARE", float("inf"))  # never grow
    fixed = _run(downlight, shown.append, photons=200_000, threads=1, batch_size=1 << 10)
    monkeypatch.undo()
    grown = _run(downlight, shown.append, photons=200_000, threads=1, batch_size=1 << 10)
    # the estimate of a 32-texel map costs far more than tracing 2048 photons
    assert fixed.iterations >= 200_000 // 2048
    assert grown.iterations < 20  # doubling: about log2 of the photon count
    assert np.array_equal(fixed.accumulator.counts(), grown.accumulator.counts())


def test_rounds_nobody_watches_are_not_estimated(downlight, monkeypatch):
    """Without progress shown or a target error, the map is estimated once, at the end,
    and that estimate is the one the last watched round gives."""
    from lumitrace.run import session

    calls = []
    real = session.estimate
    monkeypatch.setattr(session, "estimate", lambda *a: calls.append(1) or real(*a))
    shown = []
    watched = _run(downlight, shown.append, photons=200_000)
    assert len(calls) == watched.iterations == len(shown) == 3
    calls.clear()
    quiet = _run(downlight, photons=200_000)
    assert len(calls) == 1 and quiet.iterations == watched.iterations
    assert np.array_equal(quiet.accumulator.counts(), watched.accumulator.counts())
    assert quiet.estimate.error == shown[-1].relative_error
    assert np.array_equal(quiet.estimate.filtered, watched.estimate.filtered)
