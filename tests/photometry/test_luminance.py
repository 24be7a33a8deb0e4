"""The luminance table: against the third-party eulumdat-luminance reading the LDT lumitrace
writes, the Lambertian disc against its closed form, and the projected area by hand."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from lumitrace.photometry.distribution import LuminousOpening
from lumitrace.photometry.luminance import (SCREEN_LIMITS, TABLE_C, TABLE_GAMMA,
                                            luminance_table, projected_area)
from helpers.traced import traced


def test_projected_area_by_hand():
    box = LuminousOpening(0.6, 0.3, 0.05)
    # from C0 at gamma 60: the face 0.6 x 0.3 foreshortened, the side 0.3 wide, 0.05 high
    assert projected_area(box, 0.0, 60.0) == pytest.approx(0.18 * 0.5 + 0.3 * 0.05 * 0.75 ** 0.5)
    assert projected_area(box, 90.0, 60.0) == pytest.approx(0.18 * 0.5 + 0.6 * 0.05 * 0.75 ** 0.5)
    disc = LuminousOpening(0.2, 0.2, 0.0, round=True)
    assert projected_area(disc, 33.0, 45.0) == pytest.approx(math.pi * 0.01 * 0.5 ** 0.5)


@pytest.mark.parametrize("name", ["demo", "louvre", "disc"])
def test_table_against_eulumdat_luminance(name):
    pyldt = pytest.importorskip("pyldt")
    calc = pytest.importorskip("eulumdat_luminance")
    _, _, ph, ldt = traced(name)
    theirs = calc.LuminanceCalculator.compute(pyldt.LdtReader.read(str(ldt)), full=True)
    # the file's luminous length runs along C90 (the side seen from C0 is length wide), its
    # width along C0, as the package reads them: the opening as measured
    ours = luminance_table(ph.grid, ph.opening)
    cc, gg = np.meshgrid(ours.c, ours.gamma, indexing="ij")
    want = np.asarray(theirs.at(c_deg=cc.ravel(), g_deg=gg.ravel())).reshape(cc.shape)
    # the file holds 4 significant digits of cd/klm
    np.testing.assert_allclose(ours.luminance, want, rtol=2e-3)
    assert (ours.sigma > 0).all()


def test_lambertian_disc_luminance_is_flux_over_pi_area_at_every_angle():
    _, _, ph, _ = traced("disc")
    area = math.pi * 0.05 ** 2  # the stage's disc: radius 5 cm, 1000 lm downward
    assert ph.opening.area == pytest.approx(area, rel=0.02)  # as measured from exits
    table = luminance_table(ph.grid, dataclasses.replace(ph.opening, length=0.1, width=0.1))
    want = 1000.0 / (math.pi * area)
    assert table.luminance.shape == (len(TABLE_C), len(TABLE_GAMMA))
    z = (table.luminance - want) / table.sigma
    assert np.abs(z).max() < 3.0, z
    # every C plane and gamma 65 .. 85 deg: the screen maximum is the same value
    assert table.screen_max == pytest.approx(want, abs=4.0 * table.screen_max_error)
    assert 65.0 <= table.screen_max_gamma <= 85.0
    limits = table.as_dict()["luminance_screen_limits"]
    assert limits["high_state_above_200"] == {"limit": SCREEN_LIMITS["high"], "met": False}
