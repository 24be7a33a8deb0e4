"""The merit's arithmetic against closed forms: a distribution the target's shape has a
match of 0 whatever its flux (shape) and the relative difference of its scale (candela);
a figure term's residual is its relative miss, a constraint's ten times its relative
violation and 0 where met; terms and names are checked where they enter."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lumitrace.fit.objective import Measurement, Objective, parse_terms
from lumitrace.fit.parameters import FitError
from lumitrace.fit.target import Target
from lumitrace.photometry.grid import CGammaGrid


def _target() -> Target:
    gamma = np.arange(0.0, 180.0 + 1e-9, 2.5)
    cd = 1000.0 * np.clip(np.cos(np.radians(gamma)), 0, None) ** 3
    return Target(CGammaGrid(np.array([0.0]), gamma, cd[None, :], "rotational"), 0.0, 180.0,
                  1000.0, "t.ies")


def _measured(objective: Objective, scale: float, sigma: float = 0.0) -> Measurement:
    _, t, _ = objective.match_grid()
    return Measurement(scale * t, np.full_like(t, sigma), {}, 1, 0.0)


def test_a_match_of_the_targets_shape_is_zero_whatever_its_flux():
    o = Objective(_target())
    assert o.symmetry == "rotational"
    assert o.merit(_measured(o, 0.37)).match == pytest.approx(0.0, abs=1e-12)


def test_an_absolute_match_is_the_relative_difference_of_scale():
    o = Objective(_target(), absolute=True)
    assert o.merit(_measured(o, 1.1)).merit == pytest.approx(0.1, rel=1e-12)


def test_the_noise_floor_and_a_matchs_error_follow_the_grids_errors():
    """A candidate of the target's exact shape with sigma on every value: the floor is
    sqrt(sum dOmega s^2 / sum dOmega t^2) of the normalised values; a candidate 10% off
    in candela has an error sum(dOmega s d) / (D m) to first order."""
    o = Objective(_target(), absolute=True)
    _, t, omega = o.match_grid()
    m = o.merit(_measured(o, 1.1, sigma=5.0))
    den = float((omega * t * t).sum())
    assert m.noise == pytest.approx(math.sqrt(float((omega * 25.0).sum()) / den))
    d = 0.1 * t
    first = math.sqrt(float(((2 * omega * d * 5.0) ** 2).sum())) / den / (2 * 0.1)
    assert m.error == pytest.approx(first, rel=0.02)


def test_figure_terms_and_constraints():
    o = Objective(None, parse_terms(["beam_angle_c0_c180 = 30"], False),
                  parse_terms(["light_output_ratio >= 0.8", "ugr_4h8h_70_50_20 <= 19"],
                              True))
    figs = {"beam_angle_c0_c180": (33.0, 0.3), "light_output_ratio": (0.76, 0.001),
            "ugr_4h8h_70_50_20": (18.0, 0.2)}
    m = o.merit(Measurement(None, None, figs, 1, 0.0))
    # 10% off the beam's goal; 5% under the ratio's bound, weighted 10; the UGR met
    assert m.merit == pytest.approx(math.hypot(0.1, 10 * 0.04 / 0.8))
    assert not m.feasible
    assert [t["met"] for t in m.terms] == [None, False, True]
    # the error: each residual's error by its share of the merit
    want = math.hypot(0.1 * 0.3 / 30, 0.5 * 10 * 0.001 / 0.8) / m.merit
    assert m.error == pytest.approx(want)


@pytest.mark.parametrize("texts, constraints, words", [
    (["beam_width = 30"], False, "no figure 'beam_width'"),
    (["beam_angle_c0_c180 <= 30"], False, "an objective term is NAME = VALUE"),
    (["light_output_ratio = 0.8"], True, "a constraint is NAME <= VALUE"),
    (["light_output_ratio >= 1e999"], True, "must be finite"),
    (["light output ratio >= 0.8"], True, "expected NAME <= VALUE"),
])
def test_bad_terms_are_refused_naming_them(texts, constraints, words):
    with pytest.raises(FitError, match=words):
        parse_terms(texts, constraints)


def test_constraints_alone_are_refused():
    with pytest.raises(FitError, match="constraints alone"):
        Objective(None, (), parse_terms(["light_output_ratio >= 0.8"], True))
