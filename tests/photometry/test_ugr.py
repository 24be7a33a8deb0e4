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


def _file_frame(table) -> tuple:
    """(crosswise, endwise, their errors) as a reader of the LDT names them, C90 across the
    line of sight crosswise: ours, named from the luminaire's long axis, turned where it is
    long along C0."""
    if table.long_axis == "C0":
        return table.endwise, table.crosswise, table.endwise_error, table.crosswise_error
    return table.crosswise, table.endwise, table.crosswise_error, table.endwise_error


@pytest.mark.parametrize("name", ["demo", "louvre", "disc"])
def test_table_against_eulumdat_ugr(name):
    _, _, ph, ldt = traced(name)
    theirs = _their_table(ldt)
    # the file's luminous length runs along C90 (the side seen from C0 is length wide), its
    # width along C0, as eulumdat-ugr reads them: the opening as measured
    table = ugr.ugr_table(ph.grid, ph.opening)
    assert table.long_axis == {"louvre": "C0"}.get(name, "")
    cross, end, cross_err, end_err = _file_frame(table)
    ours = np.hstack([cross, end])
    err = np.hstack([cross_err, end_err])
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
    cross, end = model.evaluate(drawn.reshape(400, -1))  # C90 across crosswise
    _, _, cross_err, end_err = _file_frame(table)
    ratio = np.hstack([cross_err / cross.std(axis=0, ddof=1),
                       end_err / end.std(axis=0, ddof=1)])
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
    assert table.long_axis == "C0"  # 0.6 m along C0, 0.3 m along C90: named from C0
    cross, end, *_ = _file_frame(table)
    assert np.abs(cross - theirs[:, :5]).max() < 0.5
    # endwise, the dim C180 side of half the luminaires lowers the rating
    assert (end < theirs[:, 5:]).all()


@pytest.mark.parametrize("name", ["demo", "louvre"])
def test_one_h_spacing_against_eulumdat_ugr(name):
    """Luminaires 1.0 H apart, the observer at the table's own place: eulumdat-ugr's table
    for that spacing (its _shr 1.0, CIE 190's validation layout), 4H x 8H, 70/50/20, both
    ways (as the file names them); the variation's range holds that place's deviation."""
    pyldt = pytest.importorskip("pyldt")
    calc = pytest.importorskip("eulumdat_ugr")
    _, _, ph, ldt = traced(name)
    theirs = calc.UgrCalculator.compute(pyldt.LdtReader.read(str(ldt)), _shr=1.0).values
    i = ugr.ROOMS.index((4, 8))
    cross, end = ugr.position_ugr(ph.grid, ph.opening, 1.0)
    table = ugr.ugr_table(ph.grid, ph.opening)
    file_order = (end, cross) if table.long_axis == "C0" else (cross, end)
    assert file_order == pytest.approx((theirs[i, 0], theirs[i, 5]), abs=0.1)
    var = ugr.observer_variation(ph.grid, ph.opening)
    k = var.spacings.index(1.0)
    for here, (rise, fall), err, at in ((cross, var.crosswise[k], var.crosswise_error[k],
                                         table.catalogue()[0]),
                                        (end, var.endwise[k], var.endwise_error[k],
                                         table.catalogue(endwise=True)[0])):
        # (the table's own place is one of the variation's: equal up to rounding)
        assert fall - 1e-9 <= here - at <= rise + 1e-9 and rise >= fall
        assert (err > 0).all() and (err < 0.5).all()


def test_the_variation_grows_with_the_spacing_and_comes_from_the_draws():
    """The observer's place matters more the further apart the luminaires: the demo's
    range (rise - fall) at 2 H above that at 1 H; the errors are the draws' spread."""
    ph = traced("demo")[2]
    var = ugr.observer_variation(ph.grid, ph.opening)
    width = var.crosswise[:, 0] - var.crosswise[:, 1]
    assert width[2] > width[0] > 0
    again = ugr.observer_variation(ph.grid, ph.opening, seed=1)
    np.testing.assert_array_equal(again.crosswise, var.crosswise)  # the values: no draws
    assert np.allclose(again.crosswise_error, var.crosswise_error, rtol=0.5)


def test_lamp_flux_correction_is_exact():
    """Every luminance and the background scale with the lamps' flux: the table of lamps k
    times as strong is the table plus 8 log10 k (to rounding), the variation unchanged."""
    ph = traced("demo")[2]
    from dataclasses import replace

    one = ugr.ugr_table(ph.grid, ph.opening)
    for k in (0.5, 2.0):
        grid = replace(ph.grid, candela=ph.grid.candela * k, sigma=ph.grid.sigma * k)
        scaled = ugr.ugr_table(grid, ph.opening)
        np.testing.assert_allclose(scaled.crosswise - one.crosswise,
                                   ugr.flux_correction(1.0, k), atol=1e-9)
        np.testing.assert_allclose(scaled.crosswise_error, one.crosswise_error, rtol=1e-6)
        assert ugr.flux_correction(1200.0, 1200.0 * k) == pytest.approx(8 * math.log10(k))
    fields = ugr.flux_fields(1200.0)
    assert fields["ugr_lamp_flux"] == 1200.0
    assert fields["ugr_flux_corrections"]["2"] == pytest.approx(8 * math.log10(2), abs=1e-4)


def test_crosswise_is_named_from_the_long_axis():
    """A linear luminaire modelled along C0 and the same along C90 (its distribution turned
    90 deg with it): the same table crosswise (long axis across the line of sight) and
    endwise."""
    from lumitrace.photometry.distribution import LuminousOpening
    from lumitrace.photometry.grid import CGammaGrid, default_gammas

    gam, c = default_gammas(), np.arange(0.0, 360.0 + 1e-9, 5.0)
    cc, gg = np.meshgrid(c, gam, indexing="ij")

    def batten(long_c):  # broad across the long axis, narrow along it
        across = np.abs(np.sin(np.radians(cc - long_c)))
        return np.maximum(np.cos(np.radians(gg)), 0.0) ** (1.0 + 3.0 * (1.0 - across))

    along_c0 = CGammaGrid(c, gam, 400.0 * batten(0.0), "none", np.full(cc.shape, 1.0))
    along_c90 = CGammaGrid(c, gam, 400.0 * batten(90.0), "none", np.full(cc.shape, 1.0))
    a = ugr.ugr_table(along_c0, LuminousOpening(1.2, 0.1, 0.0))
    b = ugr.ugr_table(along_c90, LuminousOpening(0.1, 1.2, 0.0))
    assert (a.long_axis, b.long_axis) == ("C0", "C90")
    np.testing.assert_allclose(a.crosswise, b.crosswise, atol=0.02)
    np.testing.assert_allclose(a.endwise, b.endwise, atol=0.02)
    assert (a.crosswise > a.endwise + 0.5).all()  # a batten glares more seen crosswise
    va = ugr.observer_variation(along_c0, LuminousOpening(1.2, 0.1, 0.0))
    vb = ugr.observer_variation(along_c90, LuminousOpening(0.1, 1.2, 0.0))
    np.testing.assert_allclose(va.crosswise, vb.crosswise, atol=0.02)


def test_the_flux_correction_against_eulumdat_ugr(tmp_path):
    """eulumdat-ugr reads the lamp flux from the LDT's lamp set: the same distribution for
    lamps of twice the flux (the same cd/klm) rates 8 log10 2 higher, in every cell."""
    pyldt = pytest.importorskip("pyldt")
    calc = pytest.importorskip("eulumdat_ugr")
    from lumitrace.photometry.eulumdat import format_ldt
    from lumitrace.photometry.grid import CGammaGrid, default_gammas

    gam = default_gammas()
    cd = 400.0 * np.maximum(np.cos(np.radians(gam)), 0.0) ** 2
    dims = dict(length=300, width=300, height=10, lum_length=300, lum_width=300, lum_height=0)
    tables = []
    for k in (1.0, 2.0):
        grid = CGammaGrid(np.array([0.0]), gam, k * cd[None, :], "rotational", 0.01 * cd[None])
        path = tmp_path / f"lamps{k:g}.ldt"
        path.write_text(format_ldt(grid, grid.flux(), "x", dims, 1.0, 1.0), encoding="latin-1")
        tables.append(calc.UgrCalculator.compute(pyldt.LdtReader.read(str(path))).values)
    # (to the LDT's six significant digits of the lamp flux)
    np.testing.assert_allclose(tables[1] - tables[0], ugr.flux_correction(1.0, 2.0),
                               atol=2e-5)


def test_the_variations_errors_cover_a_second_seed():
    """The observer variation of the louvre traced with two seeds: its stated errors
    (redraws of the grid) cover the difference, neither too small nor too large."""
    one = ugr.observer_variation(*(lambda p: (p.grid, p.opening))(traced("louvre")[2]))
    two = ugr.observer_variation(*(lambda p: (p.grid, p.opening))(traced("louvre", seed=2)[2]))
    z = np.abs(np.stack([one.crosswise - two.crosswise, one.endwise - two.endwise])) / \
        np.hypot(np.stack([one.crosswise_error, one.endwise_error]),
                 np.stack([two.crosswise_error, two.endwise_error]))
    assert z.max() < 4.5 and np.median(z) < 1.5, z
