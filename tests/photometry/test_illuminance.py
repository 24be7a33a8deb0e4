"""Cone diagram and isolux values (inverse-square far field) of the Lambertian disc against
their closed forms: E = flux / pi cos^4(gamma) / h^2 on a plane, a 120 deg beam."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lumitrace.photometry.illuminance import DISTANCES, cone_diagram, isolux
from helpers.traced import traced


def test_lambertian_cone_diagram():
    _, _, ph, _ = traced("disc")
    cone = cone_diagram(ph.grid, ph.figures)
    i0 = 1000.0 / math.pi
    assert cone["distance_m"] == list(DISTANCES)
    for d, e, s in zip(DISTANCES, cone["centre_lux"], cone["centre_lux_error"]):
        assert e * d * d == pytest.approx(cone["centre_lux"][0], rel=1e-12)  # 1 / d^2
        assert e == pytest.approx(i0 / d ** 2, abs=4.0 * s) and 0 < s < 0.05 * e
    for plane in ("c0_c180", "c90_c270"):
        for d, w, s in zip(DISTANCES, cone[f"beam_diameter_{plane}_m"],
                           cone[f"beam_diameter_{plane}_m_error"]):
            # half of the peak at 60 deg: 2 d tan 60
            assert w == pytest.approx(2.0 * d * math.tan(math.radians(60.0)),
                                      abs=4.0 * s + 0.01 * w)


def test_lambertian_isolux():
    _, _, ph, _ = traced("disc")
    iso = isolux(ph.grid)
    x, y = np.meshgrid(iso["x_m"], iso["y_m"])
    assert iso["height_m"] == 1.0 and x.shape == (25, 25)
    cos_g = 1.0 / np.sqrt(1.0 + x * x + y * y)
    want = 1000.0 / math.pi * cos_g ** 4
    lux, err = np.array(iso["lux"]), np.array(iso["lux_error"])
    assert (err > 0).all()
    # linear interpolation between 2.5 deg gammas bends a cos^4 curve by up to ~0.2 %
    z = np.abs(lux - want) / (err + 0.003 * want)
    assert z.max() < 4.0, z.max()
    assert lux[12, 12] == pytest.approx(1000.0 / math.pi, abs=4.0 * err[12, 12])
