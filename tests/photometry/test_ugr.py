"""The UGR table (CIE 117, CIE 190 tabular method): Guth's index and one room's geometry by
hand, the rooms' flux transfer against CIE 190's own factors, and the table of traced
stages against the third-party eulumdat-ugr reading the LDT lumitrace writes."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lumitrace.photometry import guth, ugr
from helpers.traced import traced


def test_guth_formula_by_hand_and_the_table_against_it():
    # by hand: T = 0, H = R: sigma = 45 deg, tau = 0
    # ln p = (35.2 - 1.22) 1e-3 * 45 + 21e-5 * 45^2 = 1.5291 + 0.42525
    assert guth.formula_index(np.array(0.0), np.array(1.0), 1.0) == pytest.approx(
        math.exp(1.95435), rel=1e-6)
    # T = R = H: sigma = atan(sqrt 2), tau = 45 deg
    sig, tau = math.degrees(math.atan(math.sqrt(2.0))), 45.0
    a = (35.2 - 0.31889 * tau - 1.22 * math.exp(-2.0 * tau / 9.0)) * 1e-3
    b = (21.0 + 0.26667 * tau - 0.002963 * tau ** 2) * 1e-5
    assert guth.formula_index(np.array(1.0), np.array(1.0), 1.0) == pytest.approx(
        math.exp(a * sig + b * sig * sig), rel=1e-9)
    # every entry of table 4.1 within 12 % of Guth's formula (a check of its transcription)
    tr, hr = np.meshgrid(np.arange(31) * 0.1, np.arange(20) * 0.1, indexing="ij")
    ok = np.isfinite(guth.TABLE) & (hr > 0)
    formula = guth.formula_index(tr[ok], np.ones(ok.sum()), hr[ok])
    np.testing.assert_allclose(guth.TABLE[ok], formula, rtol=0.12)
    # bilinear between entries; none next to a missing entry, none beyond the table
    mid = guth.table_index(np.array([0.05]), np.array([1.0]), 1.05)[0]
    assert mid == pytest.approx(guth.TABLE[0:2, 10:12].mean())
    assert np.isnan(guth.table_index(np.array([0.1, 3.1]), np.array([1.0, 1.0]),
                                     np.array([1.85, 1.0]))).all()


def test_room_4h_by_8h_geometry_by_hand():
    h = ugr.HEIGHT
    room = ugr.room(4.0, 8.0)
    assert room.n == 16 * 32  # 4H / 0.25H across, 8H / 0.25H along
    # the rows at R = 0.25 and 0.75 m (H/R 8 and 2.7) are beyond the position index table;
    # from R = 1.25 m (H/R 1.6) every luminaire counts (T/R at most 3.75 / 1.25 = 3)
    assert len(room.t) == 30 * 16
    assert room.r.min() == pytest.approx(1.25)
    k = int(np.flatnonzero(np.isclose(room.t, 0.25) & np.isclose(room.r, 4.25))[0])
    t, r = 0.25, 4.25
    assert room.distance[k] == pytest.approx(math.sqrt(t * t + r * r + h * h), rel=1e-12)
    assert room.gamma[k] == pytest.approx(math.degrees(math.atan(math.hypot(t, r) / h)))
    # crosswise the eye is seen just off C0 (toward C360 - a), endwise off C270
    a = math.degrees(math.atan(t / r))
    assert room.c_crosswise[k] == pytest.approx(360.0 - a)
    assert room.c_endwise[k] == pytest.approx(270.0 - a)


def test_flux_transfer_gives_cie_190_table_5():
    background = pytest.importorskip("eulumdat_ugr.background")
    for i, (x, y) in enumerate(ugr.ROOMS):
        for refl, name in zip(ugr.REFLECTANCES, ugr.REFLECTANCE_NAMES):
            theirs = np.array(background._FT[name][i])  # CIE 190 table 5, as published
            ours = ugr.transfer_factors(x, y, refl)
            np.testing.assert_allclose(ours, theirs, atol=0.0015, err_msg=f"{x}x{y} {name}")


def _their_table(ldt_path) -> np.ndarray:
    pyldt = pytest.importorskip("pyldt")
    calc = pytest.importorskip("eulumdat_ugr")
    return calc.UgrCalculator.compute(pyldt.LdtReader.read(str(ldt_path))).values


@pytest.mark.parametrize("name", ["demo", "louvre", "disc"])
def test_table_against_eulumdat_ugr(name):
    _, _, ph, ldt = traced(name)
    theirs = _their_table(ldt)
    # the file's luminous length runs along C90 (the side seen from C0 is length wide), its
    # width along C0, as eulumdat-ugr reads them: the opening as measured
    table = ugr.ugr_table(ph.grid, ph.opening)
    ours = np.hstack([table.crosswise, table.endwise])
    err = np.hstack([table.crosswise_error, table.endwise_error])
    assert np.isfinite(theirs).all() and np.isfinite(ours).all()
    assert (err > 0).all()
    bad = np.abs(ours - theirs) > np.maximum(0.5, 3.0 * err)
    assert not bad.any(), (ours[bad], theirs[bad], err[bad])
    assert np.abs(ours - theirs).max() < 0.2  # in fact: both use table 4.1 and CIE 190


def test_errors_cover_a_second_seed():
    one = ugr.ugr_table(*(lambda p: (p.grid, p.opening))(traced("louvre")[2]))
    two = ugr.ugr_table(*(lambda p: (p.grid, p.opening))(traced("louvre", seed=2)[2]))
    for a, b, ea, eb in ((one.crosswise, two.crosswise, one.crosswise_error,
                          two.crosswise_error),
                         (one.endwise, two.endwise, one.endwise_error, two.endwise_error)):
        z = np.abs(a - b) / np.hypot(ea, eb)
        assert 0.3 < z.max() < 4.5 and np.median(z) < 1.5, z  # neither too small nor large
    value, error = one.catalogue()
    assert value == one.crosswise[ugr.ROOMS.index((4, 8)), 0] and error > 0


@pytest.mark.parametrize("name", ["demo", "louvre"])
def test_propagated_errors_against_a_bootstrap(name):
    # the errors are the grid's propagated to first order; 400 redraws of the grid within
    # its errors (each value it holds once) give the same spread to their own noise (3.5%)
    from lumitrace.photometry.grid import redrawn

    ph = traced(name)[2]
    table = ugr.ugr_table(ph.grid, ph.opening)
    model = ugr._model(ph.grid, ph.opening)
    drawn = redrawn(ph.grid, np.random.default_rng(5), 400)[:, ugr._unfold_index(ph.grid)]
    cross, end = model.evaluate(drawn.reshape(400, -1))
    ratio = np.hstack([table.crosswise_error / cross.std(axis=0, ddof=1),
                       table.endwise_error / end.std(axis=0, ddof=1)])
    assert 0.85 < ratio.min() and ratio.max() < 1.15, ratio
    assert 0.95 < np.median(ratio) < 1.05, np.median(ratio)


def test_a_luminaire_sending_nothing_down_has_no_rating():
    from lumitrace.photometry.distribution import LuminousOpening
    from lumitrace.photometry.grid import CGammaGrid, default_gammas
    from lumitrace.publish.record import defined

    gam = default_gammas()
    cd = 300.0 * np.maximum(-np.cos(np.radians(gam)), 0.0)[None, :]  # all light upward
    grid = CGammaGrid(np.array([0.0]), gam, cd, "rotational", 0.01 * cd)
    fields = ugr.ugr_table(grid, LuminousOpening(0.1, 0.1, 0.0, round=True)).as_dict()
    assert defined(fields["ugr_4h8h_70_50_20"]) is None
    assert defined(fields["ugr_4h8h_70_50_20_error"]) is None
    assert all(v is None for row in fields["ugr_table"]["crosswise"] for v in row)


def test_closed_form_asymmetric_grid_against_eulumdat_ugr(tmp_path):
    """No photon noise: a distribution brighter toward C0 than C180, all planes, through
    our LDT writer. Crosswise both see C0 +- atan(T/R); endwise lumitrace sees, as the
    signed T of CIE 117 gives, the C0 side of the luminaires left of the line of sight and
    the C180 side of those right of it, eulumdat-ugr takes |T| and sees the C0 side of all:
    endwise they agree only for luminaires symmetric about C90-C270."""
    pyldt = pytest.importorskip("pyldt")
    calc = pytest.importorskip("eulumdat_ugr")
    from lumitrace.photometry.distribution import LuminousOpening
    from lumitrace.photometry.eulumdat import format_ldt
    from lumitrace.photometry.grid import CGammaGrid, default_gammas

    gam, c = default_gammas(), np.arange(0.0, 360.0 + 1e-9, 5.0)
    cc, gg = np.meshgrid(c, gam, indexing="ij")
    cd = np.maximum(np.cos(np.radians(gg)), 0.0) * (
        300.0 + 200.0 * np.maximum(np.cos(np.radians(cc)), 0.0))
    grid = CGammaGrid(c, gam, cd, "none", 0.01 * cd)
    opening = LuminousOpening(0.6, 0.3, 0.0)
    path = tmp_path / "asym.ldt"
    dims = dict(length=600, width=300, height=10, lum_length=600, lum_width=300, lum_height=0)
    path.write_text(format_ldt(grid, grid.flux(), "asym", dims, 1.0, 1.0), encoding="latin-1")
    theirs = calc.UgrCalculator.compute(pyldt.LdtReader.read(str(path))).values
    table = ugr.ugr_table(grid, opening)
    assert np.abs(table.crosswise - theirs[:, :5]).max() < 0.5
    # endwise, the dim C180 side of half the luminaires lowers the rating
    assert (table.endwise < theirs[:, 5:]).all()
