"""EULUMDAT symmetry 3 (about the C90-C270 plane): the plane order that tells C90 from C270.

A distribution symmetric about the C90-C270 plane has I(C) = I(180 - C), so it is the same
toward C0 and C180; what the plane order decides is which of the C90 and C270 sides is which.
The profile here is brighter toward C90 (the photometric +Y) than toward C270. Following the
standard's formula (``Mc1 = 3 Mc / 4 + 1``, ``Mc2 = Mc1 + Mc / 2``: planes C270 .. C0 .. C90),
our writer and reader and eulumdat-py agree on it. (The ``eulumdat`` Rust bindings 0.7 read
such a file with the C90 and C270 sides swapped, so they are not used for this check.)
"""
from __future__ import annotations

import numpy as np
import pytest

from lumitrace.photometry.eulumdat import format_ldt, parse_ldt, plane_angles
from lumitrace.photometry.grid import CGammaGrid

DIMS = dict(length=100, width=100, height=10, lum_length=100, lum_width=100, lum_height=0)


def _c90_sided_grid():
    c = np.arange(90.0, 270.0 + 1e-9, 15.0)
    gam = np.arange(0.0, 91.0, 10.0)
    cd = np.array([[(100.0 + 50.0 * np.sin(np.radians(ci))) * np.cos(np.radians(g))
                    for g in gam] for ci in c])
    return CGammaGrid(c, gam, cd, "C90-C270")


def test_symmetry_3_keeps_the_c90_side_where_it_is(tmp_path):
    grid = _c90_sided_grid()
    text = format_ldt(grid, 1000.0, "c90 side", DIMS, 1.0, 1.0, dc=15.0)
    lines = text.split("\r\n")
    assert lines[2] == "3"
    cs = plane_angles(3, 24, 15.0)
    assert list(cs[:3]) == [270.0, 285.0, 300.0] and cs[6] == 0.0 and cs[-1] == 90.0
    # the data block starts with C270 (the dim side) and ends with C90 (the bright side)
    ng = len(grid.gamma)
    data = [float(v) for v in lines[-1 - 13 * ng:-1]]
    assert data[0] == pytest.approx(50.0) and data[-ng] == pytest.approx(150.0)
    ours = parse_ldt(text).grid
    at = lambda c: float(ours.at(np.array([c]))[0, 0])  # noqa: E731
    assert at(90.0) == pytest.approx(150.0) and at(270.0) == pytest.approx(50.0)
    assert at(0.0) == pytest.approx(100.0) and at(180.0) == pytest.approx(100.0)
    assert at(45.0) == pytest.approx(at(135.0)) and at(45.0) > at(315.0)

    pyldt = pytest.importorskip("pyldt")
    path = tmp_path / "c90.ldt"
    path.write_text(text, encoding="latin-1")
    full = np.asarray(pyldt.LdtReader.read(str(path)).intensities, dtype=float)
    for c in (0, 45, 90, 135, 180, 225, 270, 315):
        assert full[c // 15][0] == pytest.approx(at(float(c)), rel=1e-3), c
