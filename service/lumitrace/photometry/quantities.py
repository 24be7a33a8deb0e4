"""Figures a datasheet lists, measured from the goniophotometer's counts with their standard
errors: fluxes, ratios, the CIE flux code, the peak, beam and field angles.

CIE flux code (CIE 52): N1, N2, N3 are the shares of the downward flux within 41.4, 60 and
75.5 degrees of nadir (cones of pi/2, pi and 3 pi/2 sr), N4 the downward share of the
luminaire flux, N5 the light output ratio, all in percent. The zones are whole goniometer
cells (their edges are cell edges), so these are exact photon counts, not integrals of a
resampled grid.

The peak is the intensity at the top of the distribution, estimated without the upward bias
of a maximum of noisy values or the downward bias of a cell's mean over a curved top: each
half of the photons locates the top by a local quadratic fit, the other half's fit measures
it there (:mod:`lumitrace.photometry.peak`; where too little light lies near the top, each
half picks a cell of the grid and the other half measures it). Beam (50%) and field (10%)
angles are the outermost crossings of plane profiles with half (a tenth) of the peak (of
the plane's own largest value where the peak lies out of the plane), on a grid of the
published symmetry
with gamma every 0.5 deg (the published grid's 2.5 deg would put a step of the
distribution, such as a mirror's extra reflection, up to a degree off), and where the profile
steps at a crossing the crossing is at the step (:func:`_outer_crossing`); their errors come
from redrawing the grid within its standard errors (a parametric bootstrap, fixed seed):
each value the grid holds is drawn once, so both sides of a symmetric luminaire's profile,
which are the same values, move together.
"""
from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass

import numpy as np

from ..film.accumulate import Accumulator
from ..film.goniometer import CIE_COSINES, GAMMA_EDGES
from .grid import CGammaGrid, NormalDraws, redrawn
from .accuracy import grid_accuracy
from .measured import emitter_rings, measure_all
from .peak import Peak, fitted_peak

#: Cone half-angles (deg) of the CIE flux code, and the horizon.
CIE_ZONES = tuple(float(np.degrees(np.arccos(c))) for c in CIE_COSINES) + (90.0,)
#: A half picks the cell with the largest value less this many of its standard errors: a
#: tiny noisy cell does not win a flat top by its noise, a large cell a little below the
#: top does not win by its precision.
PICK_SIGMAS = 2.0
#: Redraws of the plane profiles for the errors of beam and field angles.
BOOTSTRAP_DRAWS = 200


@dataclass(frozen=True)
class PhotometricFigures:
    """What a datasheet lists (lm, fractions, cd, degrees), each ``*_error`` the standard
    error of the figure before it (None where the figure is undefined)."""

    luminous_flux: float
    luminous_flux_error: float
    lamp_flux: float
    light_output_ratio: float
    light_output_ratio_error: float
    downward_flux_fraction: float
    downward_flux_fraction_error: float
    upward_flux_fraction: float
    peak_intensity: float
    peak_intensity_error: float
    peak_c: float
    peak_gamma: float
    beam_angle_c0_c180: float | None
    beam_angle_c0_c180_error: float | None
    beam_angle_c90_c270: float | None
    beam_angle_c90_c270_error: float | None
    field_angle_c0_c180: float | None
    field_angle_c0_c180_error: float | None
    field_angle_c90_c270: float | None
    field_angle_c90_c270_error: float | None
    #: every crossing of the beam's level (deg from nadir, or from the zenith for a beam
    #: lighting upward; negative toward C180 or C270)
    beam_crossings_c0_c180: tuple[float, ...]
    beam_crossings_c90_c270: tuple[float, ...]
    cie_flux_code: str
    cie_flux_code_values: tuple[float, ...]
    cie_flux_code_errors: tuple[float, ...]
    photometry_error: float | None
    #: the largest relative standard error of a lit value (at least a tenth of the largest)
    #: and its (C, gamma) in degrees
    photometry_worst_error: float | None = None
    photometry_worst_at: tuple[float, float] | None = None
    #: why a beam or field angle is undefined, by its name (none where all are defined)
    spread_notes: dict | None = None

    def as_dict(self) -> dict:
        return asdict(self)


#: The figures that scale with the lights' flux (lm, cd, and their standard errors).
FLUX_SCALED = ("luminous_flux", "luminous_flux_error", "lamp_flux", "peak_intensity",
               "peak_intensity_error")


def scaled_figures(figures: dict, k: float) -> dict:
    """:meth:`PhotometricFigures.as_dict` of the same counts with every light's flux times
    ``k``: the fluxes and intensities scale, every ratio, angle and relative error stays."""
    return {name: v * k if name in FLUX_SCALED and v is not None else v
            for name, v in figures.items()}


def _ratio(a: tuple, b: tuple) -> tuple[float, float]:
    """A / B and its standard error for photon fluxes in nested groups (A within B), each
    given as (flux, variance, sum of squared photon fluxes): given B's photons, A's share
    is binomial."""
    fa, _, qa = a
    fb, _, qb = b
    if fb <= 0:
        return 0.0, math.nan
    r = fa / fb
    return r, math.sqrt(max(qa * (1.0 - 2.0 * r) + r * r * qb, 0.0)) / fb


def zone_figures(acc: Accumulator, rings: list[tuple[float, float, np.ndarray]]) -> dict:
    """Escaped and downward flux with errors, N1..N5 of the CIE flux code with errors, from
    the emitters' rings (:func:`~lumitrace.photometry.measured.emitter_rings`)."""
    edges = (*CIE_ZONES, 180.0)
    ends = [int(np.searchsorted(GAMMA_EDGES, e - 1e-9)) for e in edges]  # gamma bins below
    sums = np.zeros((3, len(edges)))  # flux, variance, squared photon fluxes per cone
    for w, total, ring in rings:
        n = np.concatenate([[0.0], np.cumsum(ring)])[ends]
        sums += [w * n, w * w * n * np.maximum(1.0 - n / total, 0.0), w * w * n]
    zones = {e: tuple(map(float, sums[:, i])) for i, e in enumerate(edges)}
    total, down = zones[180.0], zones[90.0]
    lamp = sum(t.flux for t in acc.emitters if t.photons)
    n = [_ratio(zones[e], down) for e in CIE_ZONES[:3]]
    dff = _ratio(down, total)
    lor = (total[0] / lamp, math.sqrt(total[1]) / lamp) if lamp > 0 else (math.nan, math.nan)
    values = tuple(100.0 * x for x, _ in (*n, dff, lor))
    errors = tuple(100.0 * e for _, e in (*n, dff, lor))
    return {"flux": total[0], "flux_error": math.sqrt(total[1]), "lamp": lamp,
            "lor": lor, "dff": dff, "cie": (values, errors)}


def split_peak(h0: np.ndarray, s0: np.ndarray, h1: np.ndarray, s1: np.ndarray
               ) -> tuple[float, float, int, int]:
    """The largest value of two half-photon grids' mean, without the bias of a maximum: each
    half picks a cell, the other half measures it (a choice independent of the measurement
    leaves it unbiased). The pick is the largest lower bound, value - :data:`PICK_SIGMAS`
    sigma, so a large cell measured well wins over a tiny noisy one on a flat top. Returns
    (value, standard error, cell picked by half 0, cell picked by half 1), cells as flat
    indices."""
    a0, a1 = int(np.argmax(h0 - PICK_SIGMAS * s0)), int(np.argmax(h1 - PICK_SIGMAS * s1))
    value = 0.5 * (h1.flat[a0] + h0.flat[a1])
    error = 0.5 * math.hypot(s1.flat[a0], s0.flat[a1])
    return float(value), float(error), a0, a1


def _plane_profile(grid: CGammaGrid, c_deg: float, values=None):
    """Values across the vertical plane through C (angle from nadir, negative toward
    C + 180)."""
    a = grid.at(np.array([c_deg]), values)[0]
    b = grid.at(np.array([c_deg + 180.0]), values)[0]
    return np.concatenate([-grid.gamma[::-1], grid.gamma[1:]]), np.concatenate([b[::-1], a[1:]])


def spread_angles(ang: np.ndarray, profs: np.ndarray, levels: np.ndarray,
                  sigma: np.ndarray | None = None, half=None) -> np.ndarray:
    """Full angles (deg) between the outermost crossings of every row of ``profs`` (rows,
    samples on a uniform raster) with its ``levels`` (rows,), NaN where undefined, read
    as :func:`outermost_crossings` reads them."""
    left, right = outermost_crossings(ang, profs, levels, sigma, half)
    return right - left


#: A crossing's local line is fitted over this share of its distance from the profile's
#: axis (each side), in samples, between 1 and :data:`MOST_HALF` samples each side.
FIT_SHARE = 0.1
MOST_HALF = 6


def fit_half_widths(ang: np.ndarray, profs: np.ndarray, levels: np.ndarray
                    ) -> np.ndarray:
    """Samples each side of a crossing that its line is fitted over, per row and side
    (rows, 2): :data:`FIT_SHARE` of the raw outermost crossing's distance from the axis,
    at least 1 (two samples: the two around the crossing) and at most
    :data:`MOST_HALF`."""
    above = profs >= levels[:, None]
    n = profs.shape[1]
    first = np.argmax(above, axis=1)
    last = n - 1 - np.argmax(above[:, ::-1], axis=1)
    h = ang[1] - ang[0]
    dist = np.stack([np.abs(ang[first]), np.abs(ang[last])], axis=1) / h
    return np.clip(np.round(FIT_SHARE * dist), 1, MOST_HALF).astype(np.int64)


def _smoothed(profs: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Each row's running mean over 2 ``half`` + 1 samples (fewer at the ends)."""
    n = profs.shape[1]
    cs = np.concatenate([np.zeros((len(profs), 1)), np.cumsum(profs, axis=1)], axis=1)
    k = np.arange(n)[None, :]
    lo = np.clip(k - half[:, None], 0, n)
    hi = np.clip(k + half[:, None] + 1, 0, n)
    rows = np.arange(len(profs))[:, None]
    return (cs[rows, hi] - cs[rows, lo]) / (hi - lo)


def outermost_crossings(ang: np.ndarray, profs: np.ndarray, levels: np.ndarray,
                        sigma: np.ndarray | None = None, half=None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The outermost crossings (deg, negative toward the profile's start) of every row of
    ``profs`` with its level; NaN where the profile does not fall below the level on both
    sides. Read without the outward pull of noise: the outermost sample at or above the
    level is, among noisy samples, further out the noisier they are. So each side's
    crossing is found on the profile's running mean, then read off a line fitted to the
    samples around it (``half`` samples each side, per row and side, (rows, 2); default
    :func:`fit_half_widths`), which is unbiased to first order; where the profile steps at
    the crossing (``sigma``, the samples' standard errors, tell), at the step
    (:func:`_outer_crossing`)."""
    n = profs.shape[1]
    if half is None:
        half = fit_half_widths(ang, profs, levels)
    half = np.broadcast_to(np.asarray(half, np.int64), (len(profs), 2))
    back = None if sigma is None else sigma[::-1]
    out = []
    for side, (p, s) in enumerate(((profs[:, ::-1], back), (profs, sigma))):
        smooth = _smoothed(p, half[:, side])
        above = smooth >= levels[:, None]
        last = n - 1 - np.argmax(above[:, ::-1], axis=1)
        first = np.argmax(above, axis=1)
        ok = above.any(axis=1) & (first > 0) & (last < n - 1) & (levels > 0)
        last = np.where(ok, last, n // 2)
        # the samples' own outermost crossing: where a step at the level is looked for
        raw = p >= levels[:, None]
        raw_last = np.where(raw.any(axis=1), n - 1 - np.argmax(raw[:, ::-1], axis=1), last)
        raw_last = np.where(ok & (raw_last < n - 1), raw_last, last)
        a = ang if side else -ang[::-1]
        with np.errstate(invalid="ignore", divide="ignore"):
            fitted = _fitted_crossing(a, p, levels, last, half[:, side])
            x = _outer_crossing(a, p, levels, raw_last, s, fitted)
        out.append(np.where(ok, x if side else -x, np.nan))
    return out[0], out[1]


def _fitted_crossing(ang, profs, levels, i, half):
    """Where a curve fitted to the 2 ``half`` samples around the crossing between samples
    ``i`` and ``i`` + 1 (rows; ``ang`` increasing outward) meets the level, within those
    samples: a parabola (unbiased where the profile curves, as a beam's flank does), a line
    where two samples each side are all there is; linear between the two samples where the
    fit does not fall through the level there."""
    n = profs.shape[1]
    rows = np.arange(len(profs))[:, None]
    offs = np.arange(-MOST_HALF + 1, MOST_HALF + 1)[None, :]
    use = (offs > -half[:, None]) & (offs <= half[:, None])
    k = np.clip(i[:, None] + offs, 0, n - 1)
    step = ang[1] - ang[0]
    u = offs - 0.5  # samples from the midpoint between i and i + 1
    y = profs[rows, k] - levels[:, None]
    # weighted least squares of y on (1, u, u^2), the unused samples weighted 0; a line
    # (the u^2 column dropped) where one or two samples each side are all there is
    quad = half >= 3
    cols = [np.ones_like(u, dtype=np.float64) * use, u * use, (u * u) * use * quad[:, None]]
    a = np.stack(cols, axis=2)  # (rows, samples, 3)
    ata = np.einsum("rsi,rsj->rij", a, a)
    ata[~quad, 2, 2] = 1.0  # the line's normal equations, the u^2 term held at 0
    atb = np.einsum("rsi,rs->ri", a, y * use)
    c0, c1, c2 = np.linalg.solve(ata, atb[..., None])[..., 0].T
    # the root of c0 + c1 u + c2 u^2 nearest the midpoint, where the curve falls there
    disc = c1 * c1 - 4.0 * c2 * c0
    with np.errstate(invalid="ignore", divide="ignore"):
        root = np.where(np.abs(c2) > 1e-12 * np.abs(c1),
                        -2.0 * c0 / (c1 + np.sign(c1) * np.sqrt(np.maximum(disc, 0.0))),
                        -c0 / c1)
    r = rows[:, 0]
    pi, pj = profs[r, i], profs[r, np.minimum(i + 1, n - 1)]
    with np.errstate(invalid="ignore", divide="ignore"):  # (not falling there: midway)
        linear = ang[i] + step * np.where(pi > pj, np.clip((pi - levels) / (pi - pj), 0, 1),
                                          0.5)
    # falling through the level, clearly not a tangent (the nearer root's slope is c1's
    # sign): a decision that floating rounding at another scale of the counts cannot flip
    good = (c1 < 0) & (disc > 1e-8 * c1 * c1) & (np.abs(root) <= half - 0.5)
    return np.where(good, ang[i] + step * (0.5 + root), linear)


#: Samples each side's line is fitted to where a step is looked for at a crossing.
STEP_SAMPLES = 8
#: The lines fitted on either side of a crossing, met between its two samples, differ by
#: at least this many standard errors where the profile steps there.
STEP_SIGMAS = 3.0


@functools.lru_cache(maxsize=4)
def _offsets(u: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, float, float, np.ndarray]:
    """Offsets ``u`` (samples) a line is fitted at: as an array, less their mean, the sum
    of squares of that, their mean, and the weights of the samples in the fitted line's
    value at 0.5 (midway to the next sample)."""
    u = np.array(u)
    du = u - u.mean()
    den = (du * du).sum()
    weights = 1.0 / len(u) + du * (0.5 - u.mean()) / den
    for shared in (u, du, weights):  # (made once, read by every call)
        shared.flags.writeable = False
    return u, du, den, u.mean(), weights


def _line(y: np.ndarray, u: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares lines through rows ``y`` at offsets ``u`` (samples): their values at
    the offsets' mean, their slopes (per sample) and that mean."""
    _, du, den, mean, _ = _offsets(u)
    return y.mean(axis=1), (y * du).sum(axis=1) / den, mean


def _outer_crossing(ang, profs, levels, i, sigma, smooth_reading=None):
    """Where each row falls through its level beyond sample ``i`` (its last at or above the
    level), in deg from nadir toward increasing index: linear between samples i and i + 1,
    unless the lines fitted to the :data:`STEP_SAMPLES` samples inside and outside differ
    where they meet by :data:`STEP_SIGMAS` standard errors. Then the profile steps between
    them: two samples are means over cells, so the step sits where the two lines, each up to
    it, give the two cells' sum, and the crossing is at the step when the level lies in it
    (linear interpolation across a step puts it up to a cell outward)."""
    rows = np.arange(len(profs))
    h = ang[1] - ang[0]
    pi, pj = profs[rows, i], profs[rows, i + 1]
    linear = ang[i] + h * (pi - levels) / (pi - pj) if smooth_reading is None \
        else smooth_reading
    m, n = STEP_SAMPLES, profs.shape[1]
    if sigma is None:
        return linear
    ok = (i - m > n // 2) & (i + 1 + m < n)  # inside samples past nadir (its cap is wider)
    k = np.where(ok, i, n // 2 + m + 1)[:, None]
    inside, outside = tuple(range(-m, 0)), tuple(range(2, m + 2))
    (u_in, *_, w_in), (u_out, *_, w_out) = _offsets(inside), _offsets(outside)
    k_in, k_out = np.minimum(k + u_in, n - 1), np.minimum(k + u_out, n - 1)
    a_in, b_in, c_in = _line(profs[rows[:, None], k_in], inside)
    a_out, b_out, c_out = _line(profs[rows[:, None], k_out], outside)
    # the lines' values midway between the crossing's samples, as weights of their samples
    var = ((w_in * sigma[k_in]) ** 2).sum(axis=1) + ((w_out * sigma[k_out]) ** 2).sum(axis=1)
    step = a_in + b_in * (0.5 - c_in) - a_out - b_out * (0.5 - c_out)
    ok &= step > STEP_SIGMAS * np.sqrt(var)
    if not ok.any():
        return linear

    def phi(s):  # the two lines' integral over both cells, stepping at s, less the cells'
        inner = a_in * (s + 0.5) + 0.5 * b_in * ((s - c_in) ** 2 - (0.5 + c_in) ** 2)
        outer = a_out * (1.5 - s) + 0.5 * b_out * ((1.5 - c_out) ** 2 - (s - c_out) ** 2)
        return inner + outer - pi - pj

    # phi is quadratic in s and rises through its one root in the cells (a step down)
    c0 = phi(0.0)
    b0 = a_in - b_in * c_in - a_out + b_out * c_out  # phi'(0)
    root = 2.0 * c0 / (-b0 - np.sqrt(np.maximum(b0 * b0 - 2.0 * (b_in - b_out) * c0, 0.0)))
    s = np.where(phi(-0.5) >= 0, -0.5, np.where(phi(1.5) <= 0, 1.5, np.clip(root, -0.5, 1.5)))
    top, bottom = a_in + b_in * (s - c_in), a_out + b_out * (s - c_out)
    falling_in, falling_out = np.where(b_in < 0, b_in, -np.inf), np.where(b_out < 0, b_out, -np.inf)
    u = np.where(levels > top, np.minimum(c_in + (levels - a_in) / falling_in, s),
                 np.where(levels < bottom,
                          np.maximum(c_out + (levels - a_out) / falling_out, s), s))
    return np.where(ok, ang[i] + h * u, linear)


def _step_read(every: tuple[float, ...], outer: tuple[np.ndarray, np.ndarray]
               ) -> tuple[float, ...]:
    """Every crossing, the outermost two as the beam angle reads them (at a step)."""
    if len(every) < 2:
        return every
    return (float(outer[0][0]), *every[1:-1], float(outer[1][0]))


def crossings(ang: np.ndarray, prof: np.ndarray, level: float) -> tuple[float, ...]:
    """Every angle (deg, signed from nadir) at which a profile crosses ``level`` (linear
    between samples), in order."""
    above = prof >= level
    i = np.flatnonzero(above[1:] != above[:-1])
    t = (prof[i] - level) / (prof[i] - prof[i + 1])
    return tuple(float(a) for a in ang[i] + t * (ang[i + 1] - ang[i]))


def _level(grid: CGammaGrid, halves: tuple[CGammaGrid, CGammaGrid], c_deg: float,
           peak: Peak | None) -> tuple[float, float]:
    """The top (cd, with its error) the plane's beam and field levels are fractions of:
    ``peak`` where it lies in the plane (within its fit's reach), else the plane's own
    largest value, picked by each half and measured by the other."""
    if peak is not None and _in_plane(peak, c_deg, grid.symmetry):
        return peak.value, peak.error
    p0 = (_plane_profile(halves[0], c_deg)[1],
          _plane_profile(halves[0], c_deg, halves[0].sigma)[1])
    p1 = (_plane_profile(halves[1], c_deg)[1],
          _plane_profile(halves[1], c_deg, halves[1].sigma)[1])
    top, top_err, _, _ = split_peak(p0[0], p0[1], p1[0], p1[1])
    return top, top_err


#: Redraws made at once (memory: this many copies of the grid).
DRAW_CHUNK = 50


def hemisphere_columns(ang: np.ndarray, prof: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The columns of a plane profile (``ang`` -180 .. 180 deg from nadir) in the hemisphere
    of its largest value, and their angles from that hemisphere's pole (-90 .. 90): the
    lower one about nadir, or the upper one about the zenith (a luminaire lighting the
    ceiling). Beam and field angles are read there, between the horizons, as the IES and
    CIE define them for a beam: light in the other hemisphere is not part of it."""
    if abs(ang[int(np.argmax(prof))]) <= 90.0:
        cols = np.flatnonzero(np.abs(ang) <= 90.0 + 1e-9)
        return cols, ang[cols]
    up = np.flatnonzero(ang >= 90.0 - 1e-9)
    down = np.flatnonzero((ang <= -90.0 + 1e-9) & (ang > -180.0 + 1e-9))
    return np.concatenate([up, down]), np.concatenate([ang[up] - 180.0, ang[down] + 180.0])


def plane_spreads(grid: CGammaGrid, halves: tuple[CGammaGrid, CGammaGrid],
                  rng, peak: Peak | None = None,
                  planes: tuple[float, ...] = (0.0, 90.0), fractions: tuple[float, ...] = (
                      0.5, 0.1)) -> dict:
    """The beam (``fraction`` 0.5) and field (0.1) angles in the vertical planes through
    ``planes`` (C, deg): {(c, fraction): (angle, standard error, every crossing of the level
    (deg from the pole, negative toward C + 180), why it is undefined ("" where it is
    defined))}. The angles lie in the hemisphere of the profile's top
    (:func:`hemisphere_columns`); a profile with a shoulder near the level crosses it more
    than twice, and the angle is between the outermost two, as CIE and IES read it, each
    read without the outward bias of noise (:func:`outermost_crossings`). The errors come
    from :data:`BOOTSTRAP_DRAWS` redraws of the grid within its errors (``rng``'s normal
    draws, see :func:`redrawn`: both sides of a symmetric profile are the same values and
    move together) and of the level's top within its error, each redraw read alike."""
    tops = {c: _level(grid, halves, c, peak) for c in planes}
    out, draws, columns, halfs = {}, {}, {}, {}
    for c in planes:
        ang, prof = _plane_profile(grid, c)
        cols, x = hemisphere_columns(ang, prof)
        columns[c] = (cols, x)
        sigma = _plane_profile(grid, c, grid.sigma)[1][cols]
        prof = prof[cols]
        for f in fractions:
            level = f * tops[c][0]
            draws[c, f] = []
            if not level > 0:
                out[c, f] = (None, None, (), "no photon counted in the plane")
                continue
            halfs[c, f] = fit_half_widths(x, prof[None], np.array([level]))
            outer = outermost_crossings(x, prof[None], np.array([level]), sigma, halfs[c, f])
            width = float(outer[1][0] - outer[0][0])
            if math.isnan(width):
                out[c, f] = (None, None, (), f"the profile does not fall to {f:.0%} of its "
                             "top on both sides before the horizon")
            else:
                out[c, f] = (width, None, _step_read(crossings(x, prof, level), outer), "")
    # each profile's half-planes as weights of the grid's planes (linear across them):
    # only the planes they use are redrawn
    weights = grid.at(np.array([a for c in planes for a in (c + 180.0, c)]),
                      np.eye(len(grid.c)))
    rows = np.flatnonzero(np.abs(weights).sum(axis=0) > 0)
    for start in range(0, BOOTSTRAP_DRAWS, DRAW_CHUNK):
        d = min(DRAW_CHUNK, BOOTSTRAP_DRAWS - start)
        sides = np.einsum("hk,dkg->dhg", weights[:, rows], redrawn(grid, rng, d, rows))
        z = rng.standard_normal(d)  # the top's redraw: one peak, the same in every plane
        for i, c in enumerate(planes):
            b, a = sides[:, 2 * i], sides[:, 2 * i + 1]
            cols, x = columns[c]
            profs = np.concatenate([b[:, ::-1], a[:, 1:]], axis=1)[:, cols]
            sigma = _plane_profile(grid, c, grid.sigma)[1][cols]
            top = tops[c][0] + tops[c][1] * z
            wanted = [f for f in fractions if out[c, f][0] is not None]
            if not wanted:
                continue
            # every fraction's redraws at once: the rows are computed alike, row by row
            half = np.concatenate([np.repeat(halfs[c, f], d, axis=0) for f in wanted])
            got = spread_angles(x, np.tile(profs, (len(wanted), 1)),
                                np.concatenate([f * top for f in wanted]), sigma, half)
            for f, row in zip(wanted, got.reshape(len(wanted), d)):
                draws[c, f] += row[np.isfinite(row)].tolist()
    for key, (angle, _, cross, why) in out.items():
        if angle is not None:
            d = draws[key]
            out[key] = (angle, float(np.std(d, ddof=1)) if len(d) > 1 else None, cross, why)
    return out


#: The C angles (as functions of the peak's C) that a symmetry makes the same direction.
MIRROR_IMAGES = {"none": (lambda c: c,), "C0-C180": (lambda c: c, lambda c: -c),
                 "C90-C270": (lambda c: c, lambda c: 180.0 - c),
                 "quadrant": (lambda c: c, lambda c: -c, lambda c: 180.0 - c,
                              lambda c: 180.0 + c)}


def _in_plane(peak: Peak, c_deg: float, symmetry: str = "none") -> bool:
    """Whether the peak's direction, or a mirror image of it under ``symmetry``, lies in the
    vertical plane through ``c_deg`` (within :data:`IN_PLANE_DEG`; every plane holds a peak
    at a pole, and of a rotationally symmetric luminaire)."""
    if symmetry == "rotational" or peak.gamma <= IN_PLANE_DEG \
            or peak.gamma >= 180.0 - IN_PLANE_DEG:
        return True
    sin_gamma = math.sin(math.radians(peak.gamma))
    # angular distance of a direction from the plane: asin(sin gamma |sin(C - C_plane)|)
    return any(math.degrees(math.asin(min(1.0, sin_gamma * abs(math.sin(math.radians(
        image(peak.c) - c_deg)))))) <= IN_PLANE_DEG
        for image in MIRROR_IMAGES.get(symmetry, MIRROR_IMAGES["none"]))


#: A peak this close (deg) to a vertical plane is that plane's top.
IN_PLANE_DEG = 2.5


#: Gamma raster (deg) of the profiles beam and field angles are read from.
PROFILE_GAMMAS = np.arange(0.0, 180.0 + 1e-9, 0.5)


def figures(acc: Accumulator, grid: CGammaGrid, halves: tuple[CGammaGrid, CGammaGrid],
            c_step: float, rings: list | None = None, half_width: float | None = None
            ) -> PhotometricFigures:
    """The datasheet figures of the goniophotometer's counts and the published ``grid``
    and the same grid from each half of the photons (with standard errors, measured by
    :func:`~lumitrace.photometry.measured.measure_all`); ``rings``: the emitters' rings
    when the caller has them; ``half_width``: the beam's half width (deg, None where it
    never halves), which sizes the peak's fit."""
    z = zone_figures(acc, rings if rings is not None else emitter_rings(acc))
    fine = measure_all(acc, PROFILE_GAMMAS, c_step, (grid.symmetry,))
    profiles = fine[grid.symmetry, None], (fine[grid.symmetry, 0], fine[grid.symmetry, 1])
    peak, peak_err, a0, a1 = split_peak(halves[0].candela, halves[0].sigma,
                                        halves[1].candela, halves[1].sigma)
    picks = [np.unravel_index(a, grid.candela.shape) for a in (a0, a1)]
    top = fitted_peak(acc, tuple((float(grid.c[i]), float(grid.gamma[j])) for i, j in picks),
                      half_width, grid.symmetry) if grid.candela.max() > 0 else None
    if top is None:  # too little light near the top for a fit: the cells' split estimate
        i, j = picks[0] if grid.candela.flat[a0] >= grid.candela.flat[a1] else picks[1]
        top = Peak(peak, peak_err, float(grid.c[i]), float(grid.gamma[j]))
    accuracy = grid_accuracy(grid, c_step)
    rng = NormalDraws(0)
    spreads = plane_spreads(*profiles, rng, top)
    values, errors = z["cie"]
    code = " ".join(str(int(round(v))) for v in values)
    dff, dff_err = z["dff"]
    return PhotometricFigures(
        luminous_flux=z["flux"], luminous_flux_error=z["flux_error"], lamp_flux=z["lamp"],
        light_output_ratio=z["lor"][0], light_output_ratio_error=z["lor"][1],
        downward_flux_fraction=dff, downward_flux_fraction_error=dff_err,
        upward_flux_fraction=1.0 - dff if z["flux"] > 0 else 0.0,
        peak_intensity=top.value, peak_intensity_error=top.error,
        peak_c=top.c, peak_gamma=top.gamma,
        beam_angle_c0_c180=spreads[0.0, 0.5][0], beam_angle_c0_c180_error=spreads[0.0, 0.5][1],
        beam_angle_c90_c270=spreads[90.0, 0.5][0],
        beam_angle_c90_c270_error=spreads[90.0, 0.5][1],
        field_angle_c0_c180=spreads[0.0, 0.1][0],
        field_angle_c0_c180_error=spreads[0.0, 0.1][1],
        field_angle_c90_c270=spreads[90.0, 0.1][0],
        field_angle_c90_c270_error=spreads[90.0, 0.1][1],
        beam_crossings_c0_c180=spreads[0.0, 0.5][2],
        beam_crossings_c90_c270=spreads[90.0, 0.5][2],
        spread_notes={f"{kind}_angle_{plane}": spreads[c, f][3]
                      for kind, f in (("beam", 0.5), ("field", 0.1))
                      for plane, c in (("c0_c180", 0.0), ("c90_c270", 90.0))
                      if spreads[c, f][3]} or None,
        cie_flux_code=code, cie_flux_code_values=values, cie_flux_code_errors=errors,
        photometry_error=accuracy.rms if acc.spread_known else None,
        photometry_worst_error=accuracy.worst if acc.spread_known else None,
        photometry_worst_at=accuracy.worst_at if acc.spread_known else None)
