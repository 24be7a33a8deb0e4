"""A candidate's merit, with its standard error: how far it is from what is asked.

**Target match.** The solid-angle-weighted RMS relative difference of the candidate's
distribution from the target's,
``m = sqrt(sum dOmega (a - t)^2 / sum dOmega t^2)``, over the values of a C-gamma grid
(planes every 5 deg, gammas every 2.5 deg, finer across a target beam narrower than 5 deg
half width): the candidate's point values as lumitrace's files state them, the target's
interpolated there, in the target's symmetry (the candidate's counts averaged over the
mirror images the target declares, as lumitrace's own files average them). By default
the shape alone is compared: ``a`` and ``t`` are each distribution over its own total
flux (cd/klm of the light leaving the luminaire), so a candidate that sends out less light
is not penalised for it; ``absolute`` compares candela.

**Figures.** Terms ``NAME = VALUE`` add ``((f - VALUE) / |VALUE|)^2`` to the square of the
merit; constraints ``NAME <= VALUE`` and ``NAME >= VALUE`` add ``(10 v)^2``, ``v`` the
relative violation (0 where met). Names are the result record's figures that carry a
standard error (``light_output_ratio``, ``beam_angle_c0_c180``, ``ugr_4h8h_70_50_20``,
...).

**Errors.** Photon noise is the only noise: the grid's values and the figures carry exact
standard errors, and the merit's follows from them: the variance of ``m^2`` for Gaussian
noise about the true differences, the second-order part of the noise, which the observed
differences already hold, taken off (over 24 seeds of the mirror cup the spread of a merit
was 0.87-0.95 of its stated error); the terms' errors are combined as independent. The
*noise floor* is the merit a perfect candidate would show at the same photons:
``sqrt(sum dOmega s^2 / sum dOmega t^2)``.
"""
from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..photometry.grid import default_gammas
from ..photometry.measured import cell_solid_angle_grid, planes_kept
from .parameters import FitError
from .target import Target

#: C step (deg) of the grid the match is judged on (the published files' step).
C_STEP = 5.0
#: A target beam whose half width (deg, where its mean profile falls to half its peak) is
#: below this is matched on a finer gamma grid across it.
NARROW_HALF_WIDTH = 5.0
#: Weight of a constraint's relative violation in the merit.
CONSTRAINT_WEIGHT = 10.0
#: Symmetries a match may be judged in.
SYMMETRIES = ("none", "rotational", "quadrant", "C0-C180", "C90-C270")

#: The figures a term may name: each comes with ``NAME_error`` in the record.
FIGURES = ("luminous_flux", "light_output_ratio", "downward_flux_fraction", "peak_intensity",
           "beam_angle_c0_c180", "beam_angle_c90_c270", "field_angle_c0_c180",
           "field_angle_c90_c270", "ugr_4h8h_70_50_20", "ugr_4h8h_70_50_20_endwise")
#: Of those, the ones the UGR table gives (the luminance tables' work, only when asked).
TABLE_FIGURES = ("ugr_4h8h_70_50_20", "ugr_4h8h_70_50_20_endwise")

_TERM = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(<=|>=|==|=)\s*([-+0-9.eE]+)\s*$")


@dataclass(frozen=True)
class Term:
    """A figure term (``op`` "=") or constraint ("<=", ">="), as given in ``text``."""

    name: str
    op: str
    value: float
    text: str

    def residual(self, f: float | None, sigma: float | None) -> tuple[float, float]:
        """(dimensionless residual, its standard error) of a figure ``f`` +- ``sigma``:
        relative to the goal (absolute where the goal is 0); a constraint's is its
        weighted violation, 0 where met. An undefined figure (no beam crossing, say)
        counts as a residual of 1."""
        scale = abs(self.value) if self.value != 0 else 1.0
        if f is None or not math.isfinite(f):
            return (1.0 if self.op == "=" else CONSTRAINT_WEIGHT), 0.0
        s = (sigma or 0.0) / scale
        if self.op == "=":
            return (f - self.value) / scale, s
        over = (f - self.value) if self.op == "<=" else (self.value - f)
        if over <= 0:
            return 0.0, 0.0
        return CONSTRAINT_WEIGHT * over / scale, CONSTRAINT_WEIGHT * s

    def met(self, f: float | None) -> bool:
        if f is None:
            return False
        return f <= self.value if self.op == "<=" else f >= self.value if self.op == ">=" \
            else True


def parse_terms(texts: list[str] | None, constraints: bool) -> tuple[Term, ...]:
    """``--objective`` (``NAME = VALUE``) or ``--constrain`` (``NAME <= VALUE``, ``NAME >=
    VALUE``) arguments; a :class:`FitError` naming a bad one."""
    out = []
    for text in texts or ():
        flag = "--constrain" if constraints else "--objective"
        m = _TERM.match(text)
        if not m:
            form = "NAME <= VALUE or NAME >= VALUE" if constraints else "NAME = VALUE"
            raise FitError(f"expected {form}", f"{flag} {text}")
        name, op, value = m.group(1), m.group(2), m.group(3)
        op = "=" if op == "==" else op
        if name not in FIGURES:
            near = difflib.get_close_matches(name, FIGURES, n=2, cutoff=0.5)
            hint = f"did you mean {' or '.join(near)}? " if near else ""
            raise FitError(f"no figure {name!r}: {hint}the figures are {', '.join(FIGURES)}",
                           f"{flag} {text}")
        if constraints and op == "=":
            raise FitError("a constraint is NAME <= VALUE or NAME >= VALUE (a goal NAME = "
                           "VALUE is an --objective)", f"{flag} {text}")
        if not constraints and op != "=":
            raise FitError("an objective term is NAME = VALUE (a bound is a --constrain)",
                           f"{flag} {text}")
        try:
            v = float(value)
        except ValueError:
            raise FitError(f"{value!r} is not a number", f"{flag} {text}") from None
        if not math.isfinite(v):
            raise FitError("the value must be finite", f"{flag} {text}")
        out.append(Term(name, op, v, text.strip()))
    return tuple(out)


@dataclass(frozen=True)
class Needs:
    """What a traced candidate must give for its merit (computed where its counts are):
    the match grid (``symmetry``, ``gammas``; None: no target) and the figures."""

    symmetry: str | None
    gammas: tuple[float, ...]
    figures: tuple[str, ...]

    @property
    def tables(self) -> bool:
        return any(f in TABLE_FIGURES for f in self.figures)


@dataclass(frozen=True)
class Measurement:
    """A traced candidate's part of its merit: the grid's values and standard errors (cd,
    kept planes by gammas; None without a target), the figures asked for (value, error),
    the photons and the escaped flux (lm)."""

    candela: np.ndarray | None
    sigma: np.ndarray | None
    figures: dict
    photons: int
    escaped_lm: float
    #: the grid from each of the two independent halves of the photons: ((cd, sigma),
    #: (cd, sigma)), None without a target
    halves: tuple | None = None


@dataclass(frozen=True)
class Merit:
    """A candidate's merit and standard error, its noise floor, and its parts."""

    merit: float
    error: float
    noise: float
    match: float | None = None
    match_error: float | None = None
    terms: tuple = ()
    feasible: bool = True
    #: the merit from each half of the photons (None without a target): two independent
    #: measurements with common random numbers across candidates
    halves: tuple[float, float] | None = None

    def as_dict(self) -> dict:
        return {"merit": self.merit, "merit_error": self.error, "noise_floor": self.noise,
                "match": self.match, "match_error": self.match_error,
                "terms": list(self.terms), "feasible": self.feasible}


@dataclass
class Objective:
    """The merit of a fit: the target match (``target`` None: none), figure ``terms`` and
    ``constraints``."""

    target: Target | None
    terms: tuple[Term, ...] = ()
    constraints: tuple[Term, ...] = ()
    absolute: bool = False
    symmetry: str | None = None  # the match's; default the target's
    _grid: tuple | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.target is None and not self.terms and not self.constraints:
            raise FitError("nothing to fit to: give --target FILE or --objective NAME=VALUE")
        if self.target is None and not self.terms:
            raise FitError("constraints alone leave nothing to optimise: add --objective "
                           "NAME=VALUE or --target FILE")
        if self.target is not None:
            sym = self.symmetry or self.target.symmetry
            if sym not in SYMMETRIES:
                raise FitError(f"unknown symmetry {sym!r}: one of {', '.join(SYMMETRIES)}",
                               "--symmetry")
            self.symmetry = sym

    @property
    def needs(self) -> Needs:
        names = tuple(dict.fromkeys(t.name for t in self.terms + self.constraints))
        return Needs(self.symmetry if self.target is not None else None,
                     tuple(self.gammas().tolist()) if self.target is not None else (), names)

    def gammas(self) -> np.ndarray:
        """The match grid's gammas: every 2.5 deg, and finer within three half-widths of a
        target beam narrower than :data:`NARROW_HALF_WIDTH` (a step of half its half
        width, on the goniophotometer's 0.5 deg raster): a point value's noise grows as
        its neighbours close in, so the grid is no finer than the target's shape needs."""
        g = default_gammas()
        hw = self.target.half_width() if self.target is not None else None
        if hw is not None and hw < NARROW_HALF_WIDTH:
            step = max(0.5, 0.5 * math.floor(hw))  # half the half width, on 0.5 deg
            fine = np.arange(0.0, min(180.0, 3.0 * max(hw, 1.0)) + 1e-9, step)
            g = np.unique(np.round(np.concatenate([g, fine, 180.0 - fine]) * 2.0) / 2.0)
        return g

    def match_grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(C of the kept planes (deg), the target's values there (cd), the cells' solid
        angles (sr)), each (kept planes, gammas), made once."""
        if self._grid is None:
            g = self.gammas()
            n = int(round(360.0 / C_STEP))
            rep, kept = planes_kept(self.symmetry, n)
            omega_full = cell_solid_angle_grid(g, C_STEP)
            slot = np.full(n, -1, np.int64)
            slot[kept] = np.arange(len(kept))
            omega = np.zeros((len(kept), len(g)))
            np.add.at(omega, slot[rep], omega_full)
            c = kept * C_STEP
            self._grid = (c, self.target.values(c, g), omega)
        return self._grid

    def merit(self, m: Measurement) -> Merit:
        """The merit of a traced candidate (see the module's docstring)."""
        parts, squares, variances, noise = [], 0.0, 0.0, 0.0
        match = match_error = None
        if self.target is not None:
            match, match_error, noise = self._match(m.candela, m.sigma)
            squares += match * match
            variances += (match * match_error) ** 2
        feasible = True
        for term in self.terms + self.constraints:
            f, s = m.figures.get(term.name, (None, None))
            r, rs = term.residual(f, s)
            squares += r * r
            variances += (r * rs) ** 2
            feasible &= term.op == "=" or term.met(f)
            parts.append({"term": term.text, "name": term.name, "value": f, "error": s,
                          "residual": r, "met": term.met(f) if term.op != "=" else None})
        merit = math.sqrt(squares)
        error = math.sqrt(variances) / merit if merit > 0 else 0.0
        if self.target is not None and merit > 0 and match == merit:
            error = match_error  # the match alone: its own error, second order included
        halves = None
        if self.target is not None and m.halves is not None:
            rest = squares - match * match
            halves = tuple(math.sqrt(self._match(cd, s)[0] ** 2 + rest) for cd, s in m.halves)
        return Merit(merit, error, noise, match, match_error, tuple(parts), feasible, halves)

    def _match(self, cd: np.ndarray, sigma: np.ndarray) -> tuple[float, float, float]:
        """(m, its standard error, the noise floor) of the candidate's grid."""
        _, t, omega = self.match_grid()
        cd, sigma = np.asarray(cd, np.float64), np.asarray(sigma, np.float64)
        if self.absolute:
            a, s, tn, c = cd, sigma, t, 0.0
        else:
            phi = float((omega * cd).sum())
            if not phi > 0:
                return 1.0, 0.0, 0.0  # no light left the luminaire: as far as can be
            a, s = cd / phi, sigma / phi
            tn = t / float((omega * t).sum())
        d = a - tn
        den = float((omega * tn * tn).sum())
        m2 = float((omega * d * d).sum()) / den
        if not self.absolute:
            c = float((omega * d * a).sum())
        # var(m^2) for Gaussian noise s about the true differences: sum (2 dOmega / D)^2
        # (d_true^2 s^2 + s^4 / 2); the observed d^2 holds s^2 more than d_true^2, so the
        # second-order term is taken off rather than added (floored at half the first)
        grad = 2.0 * omega * (d - c) / den  # d(m^2)/d(a_j), the normaliser's part included
        first = float(((grad * s) ** 2).sum())
        var_m2 = max(first - 2.0 * float(((omega * s * s) ** 2).sum()) / den ** 2,
                     0.5 * first)
        m = math.sqrt(m2)
        noise = math.sqrt(float((omega * s * s).sum()) / den)
        error = math.sqrt(var_m2) / (2.0 * m) if m > 0 else math.sqrt(math.sqrt(var_m2))
        return m, error, noise
