"""The figures a lighting engineer's datasheet and tender need beyond the files, all from the
same counts and grid with their standard errors: the UGR table (with CIE 190's variation of
the observer position and the lamp flux it refers to), the luminance table and the
screen-work limits, the BUG rating and the cone diagram with isolux values. One dict, keyed
as the result record is (:data:`lumitrace.schema.RESULT_FIELDS`)."""
from __future__ import annotations

from ..film.accumulate import Accumulator
from .bug import bug_rating
from .illuminance import cone_diagram, isolux
from .luminance import luminance_table
from .ugr import flux_fields, observer_variation, ugr_table


def application_figures(ph, acc: Accumulator, bug_forward: str = "C0") -> dict:
    """The record's UGR, luminance, BUG and illuminance fields of a
    :class:`~lumitrace.photometry.distribution.Photometry` and its counts; the UGR and
    luminance fields are None (not applicable) where no opening is meaningful
    (:attr:`~lumitrace.photometry.opening.LuminousOpening.meaningful`) or no light
    leaves. ``bug_forward``: the BUG rating's forward direction (C0, C90, C180, C270)."""
    out = {**bug_rating(acc, bug_forward).as_dict(), "cone_diagram": cone_diagram(ph.grid, ph.figures),
           "isolux": isolux(ph.grid)}
    if ph.opening.meaningful and ph.figures.luminous_flux > 0:
        out.update(ugr_table(ph.grid, ph.opening).as_dict())
        out.update(observer_variation(ph.grid, ph.opening).as_dict())
        out.update(flux_fields(ph.lamp_flux))
        out.update(luminance_table(ph.grid, ph.opening).as_dict())
    return out
