"""The curves an engineer reads (:mod:`lumitrace.photometry.curves`): a plane through the
grid with its error band, the beam and field angles marked where the record has them."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from lumitrace.photometry.curves import draw_cartesian, draw_polar, plane_curve  # noqa: E402
from lumitrace.photometry.grid import CGammaGrid  # noqa: E402

GAMMA = np.array([0.0, 30.0, 60.0, 90.0])
#: Planes C0, C90, C180, C270 with distinct values, and their standard errors.
CANDELA = np.array([[10.0, 8.0, 4.0, 0.0], [10.0, 6.0, 3.0, 0.0],
                    [10.0, 5.0, 2.0, 0.0], [10.0, 7.0, 1.0, 0.0]])
GRID = CGammaGrid(np.array([0.0, 90.0, 180.0, 270.0]), GAMMA, CANDELA, "none", 0.1 * CANDELA)
FIGURES = {"beam_angle_c0_c180": 70.0, "beam_angle_c90_c270": 66.0,
           "field_angle_c0_c180": 120.0, "field_angle_c90_c270": 110.0,
           "peak_intensity": 10.0, "peak_c": 0.0, "peak_gamma": 0.0}


def test_a_plane_runs_from_its_opposite_half_through_nadir():
    ang, cd, sigma = plane_curve(GRID, 0.0, 1000.0 / 500.0)
    assert ang.tolist() == [-90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0]
    assert cd.tolist() == [0.0, 4.0, 10.0, 20.0, 16.0, 8.0, 0.0]  # C180 left, C0 right
    assert np.allclose(sigma, 0.1 * cd)
    ang, cd, _ = plane_curve(GRID, 90.0, 1.0)
    assert cd.tolist() == [0.0, 1.0, 7.0, 10.0, 6.0, 3.0, 0.0]  # C270 left, C90 right


def test_beam_and_field_angles_are_marked_on_both_diagrams():
    fig = plt.figure()
    polar = fig.add_subplot(1, 2, 1, projection="polar")
    draw_polar(polar, GRID, 500.0, FIGURES)
    # two curves, a ray each side for the beam and the field of each plane, the peak
    assert len(polar.lines) == 2 + 2 * 2 * 2 + 1
    rays = sorted(round(float(np.degrees(line.get_xdata()[1])), 6) for line in polar.lines
                  if len(line.get_xdata()) == 2 and line.get_xdata()[0] == 0)
    assert rays == sorted([35.0, -35.0, 33.0, -33.0, 60.0, -60.0, 55.0, -55.0])
    cart = fig.add_subplot(1, 2, 2)
    draw_cartesian(cart, GRID, 500.0, FIGURES)
    verticals = sorted(line.get_xdata()[0] for line in cart.lines
                       if line.get_xdata()[0] == line.get_xdata()[-1])
    assert verticals == sorted([-35.0, 35.0, -33.0, 33.0, -60.0, 60.0, -55.0, 55.0])
    assert cart.get_xlim() == (-90.0, 90.0)  # 1.5 field half-angles, at most the horizon
    plt.close(fig)
