"""A real, published IES file read by our reader and by third-party readers.

``tests/data/photometry/bega_50988_lm63_1995.ies`` is a manufacturer's LM-63-1995 file
(absolute photometry, rotationally symmetric, circular opening in the 1995 convention); its
licence is beside it. Its ``[LAMP]`` keyword states the luminaire's flux, 1218 lm, which the
zonal integral of its candela table must give back.
"""
from __future__ import annotations


import numpy as np
import pytest

from helpers.paths import NO_EULUMDAT

from lumitrace.photometry.lm63 import format_ies, parse_ies, read_ies
from helpers.paths import DATA

DATA = DATA / "photometry"
BEGA = DATA / "bega_50988_lm63_1995.ies"
STATED_FLUX = 1218.0  # lm, from the file's [LAMP] keyword


def test_public_lm63_1995_file_reads_correctly():
    ies = read_ies(BEGA)
    assert ies.version == "LM-63-1995"
    assert ies.keywords["MANUFAC"] == "BEGA Copyright LUMCat V"  # [MORE] continues it
    assert ies.keywords["LUMINAIRE"] == "50988.2K3"
    assert ies.lumens_per_lamp == -1.0  # absolute photometry
    assert (ies.width, ies.length, ies.height) == (-0.12, 0.0, 0.0)  # 1995: a 12 cm circle
    assert ies.input_watts == 14.0
    grid = ies.grid()
    assert grid.symmetry == "rotational"
    assert grid.gamma[0] == 0.0 and grid.gamma[-1] == 180.0  # nothing above the horizon
    assert grid.candela[0, 0] == pytest.approx(2225.9)
    assert grid.candela[0, 36] == 0.0
    assert grid.peak == (pytest.approx(2225.9), 0.0, 0.0)
    assert grid.flux() == pytest.approx(STATED_FLUX, rel=1e-3)


def test_public_file_agrees_with_third_party_readers():
    eulumdat = pytest.importorskip("eulumdat", reason=NO_EULUMDAT)  # AGPL: tests only
    eulumdat_ies = pytest.importorskip("eulumdat_ies")
    ours = read_ies(BEGA).grid()
    theirs = eulumdat.Eulumdat.from_ies_file(str(BEGA))
    flux = theirs.total_luminous_flux()
    # the Rust reader integrates with the trapezoid rule, we by zones: same flux to 0.5 %
    assert flux == pytest.approx(ours.flux(), rel=5e-3)
    assert theirs.max_intensity() * flux / 1000.0 == pytest.approx(2225.9, rel=1e-6)
    for gamma in (0.0, 20.0, 40.0, 60.0):
        j = int(np.argmin(np.abs(ours.gamma - gamma)))
        assert theirs.sample(0.0, gamma) * flux / 1000.0 == pytest.approx(
            ours.candela[0, j], rel=1e-6)
    with pytest.warns(UserWarning):  # absolute photometry: it keeps cd as they are
        ldt = eulumdat_ies.ies_to_ldt(str(BEGA))
    np.testing.assert_allclose(np.asarray(ldt.intensities[0], float),
                               ours.candela[0, :37], rtol=1e-9)


def test_public_file_survives_our_writer(tmp_path):
    eulumdat = pytest.importorskip("eulumdat", reason=NO_EULUMDAT)
    grid = read_ies(BEGA).grid()
    text = format_ies(grid, STATED_FLUX, -0.12, -0.12, 0.0, {"MANUFAC": "BEGA"})
    back = parse_ies(text).grid()
    np.testing.assert_allclose(back.candela, grid.candela, rtol=1e-6)
    path = tmp_path / "bega.ies"
    path.write_text(text, encoding="utf-8")
    theirs = eulumdat.Eulumdat.from_ies_file(str(path))
    for gamma in (0.0, 30.0, 45.0):
        j = int(np.argmin(np.abs(grid.gamma - gamma)))
        cd = theirs.sample(0.0, gamma) * theirs.total_luminous_flux() / 1000.0
        assert cd == pytest.approx(grid.candela[0, j], rel=1e-5)
