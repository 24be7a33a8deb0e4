"""The luminous opening: the outline the light leaves the luminaire through (LM-63's
luminous dimensions, EULUMDAT's luminous area), which the luminance and UGR tables divide
the intensity by.

Measured from where photons leave the luminaire's bounding box, at their exact crossing
points: the photons ``0 .. n - 1`` of each emitter (the run's own first photons, traced
again with its seed; :data:`OPENING_PHOTONS` at most). The box face most of the light
leaves through (its bottom, or its top for a luminaire that sends more light up) holds the
flat opening; the sides give its luminous height where they carry light.

An edge is where the light ends. The bins of a profile across it that still hold
:data:`EDGE_LEVEL` of the opening's typical exitance locate it to a bin; there, on the
photons' own positions, it follows the outermost photon still within the light (reached
without a gap many mean spacings wide, and with less light beyond it than the edge level),
one mean spacing of the last photons further: the gap from a Poisson sample's last point to
its edge is exponential, that spacing its mean and its spread, the edge's standard error.
A rectangular opening has its edges along C0 and C90; a round one its centre and shape from
the edges along 16 rays from its centre (an ellipse fitted through them, a circle where its
axes agree), its size from the edge of all its light along the ellipse's radius, its error
that edge's or the rays' scatter where that is larger (a polygon's corners, a rim that
fades). No part of the estimate trims light: a disc's edge is its rim.

Where more than :data:`STRAY_LIMIT` of the face's light leaves outside the outline, or
the light has no edge (the outline's outer tenth less than :data:`RIM_LEVEL` as bright as
its inside: it leaves from everywhere, as through the Fresnel slab's 40 m of glass) no
opening is meaningful: the opening is none, and the tables that need one are not
applicable, unless the stage declares one (``lumitrace:luminousOpeningShape`` and
``lumitrace:luminousOpening``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

#: Photons whose exits measure the opening (at most; a run of fewer traces as many as it
#: did, at least :data:`MIN_OPENING_PHOTONS`: with 8,192 the demo's diffuser, whose light
#: fades to its rim, reads up to 10% wide, beyond its stated error).
OPENING_PHOTONS = 1 << 16
MIN_OPENING_PHOTONS = 1 << 15
#: Light fainter than this share of the opening's typical exitance (the level half its
#: light leaves at or above) does not make an edge: a faint glow beyond a louvre's last
#: blade is not its opening.
EDGE_LEVEL = 0.05
#: Expected photons in a profile bin at the edge level: sets the bins that locate an edge.
EDGE_PHOTONS = 10
#: Share of the face's light outside the outline above which no opening is meaningful.
STRAY_LIMIT = 0.01
#: Exitance of the outline's outer tenth, against its inside's, below which the light has
#: no edge (it fades out: the Fresnel slab's 1.5%; a diffuser's rim is half as bright as
#: its middle, a parabolic reflector's opening a third)
RIM_LEVEL = 0.1
#: Below this share of the escaping flux, the sides of the box have no luminous height.
SIDE_SHARE = 0.01
#: The sides' light counts toward the luminous height where it is this share of its
#: typical level (light through a louvre's open ends falls in a band, with a faint tail
#: below it)
HEIGHT_LEVEL = 0.1
#: A luminaire is linear (EULUMDAT's Ityp 2) where its luminous opening (its box where it
#: has none) is at least this many times as long as it is wide.
LINEAR_RATIO = 1.5
#: Rays from the centre along which a round opening's edge is found (its centre and shape).
SECTORS = 16
#: A flat opening is round when at most this share of the light within its extents leaves
#: outside the ellipse inscribed in them (a square sends a fifth of its light through its
#: corners).
ROUND_OPENING_OUTSIDE = 0.02


@dataclass(frozen=True)
class LuminousOpening:
    """Luminous dimensions (m) in the photometric frame, along C0, along C90 and vertical,
    and the opening's centre (m, photometric-frame coordinates).

    ``source`` says where it comes from: ``measured`` (from the photons' exits, with
    standard errors ``error``), ``declared`` (the stage's ``lumitrace:luminousOpening``)
    or ``none`` (no opening is meaningful, ``note`` says why; its dimensions are 0)."""

    length: float
    width: float
    height: float
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: the opening is round (a circle where length equals width, else an ellipse): the
    #: light leaves its face within the ellipse inscribed in the extents
    round: bool = False
    #: the luminaire's own extents (m) along C0, C90 and vertical (its bounding box)
    box: tuple[float, float, float] = (0.0, 0.0, 0.0)
    source: str = "measured"
    #: standard errors (m) of length, width and height
    error: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: why no opening is meaningful, or what was measured
    note: str = ""
    #: share of the face's light that leaves outside the outline
    outside: float = 0.0
    #: photons whose exits measured it
    photons: int = 0

    @property
    def area(self) -> float:
        """The luminous area (m^2) of the flat opening: an ellipse's or a rectangle's."""
        return (math.pi / 4.0 if self.round else 1.0) * self.length * self.width

    @property
    def meaningful(self) -> bool:
        """Whether the luminaire has an opening that luminance and UGR can divide by."""
        return self.source != "none" and (self.area > 0 or self.height > 0)

    @property
    def shape(self) -> str:
        return "round" if self.round else "rectangular"

    def as_dict(self) -> dict:
        """The record's fields."""
        return {"luminous_opening": (self.length, self.width, self.height),
                "luminous_opening_error": tuple(self.error),
                "luminous_opening_shape": self.shape,
                "luminous_opening_source": self.source,
                "luminous_opening_note": self.note}


# -- the edge of the light along one coordinate ----------------------------------------

def _histogram(v: np.ndarray, w: np.ndarray, lo: float, hi: float, n: int) -> np.ndarray:
    """``w`` summed in ``n`` bins of ``lo`` .. ``hi`` (both ends in; values beyond left out)."""
    inside = (v >= lo) & (v <= hi)
    v, w = v[inside], w[inside]
    k = ((v - lo) / (hi - lo) * n).astype(np.int64) if hi > lo else np.zeros(len(v), np.int64)
    return np.bincount(np.clip(k, 0, n - 1), w, n)


def _typical(level: np.ndarray, weight: np.ndarray) -> float:
    """The level half of ``weight`` lies at or above (the flux-weighted median)."""
    order = np.argsort(level)[::-1]
    cum = np.cumsum(weight[order])
    return float(level[order][min(np.searchsorted(cum, 0.5 * cum[-1]), len(order) - 1)])


def _bins(photons: int) -> int:
    """Profile bins for ``photons``: :data:`EDGE_PHOTONS` expected at the edge level."""
    return int(np.clip(photons * EDGE_LEVEL / EDGE_PHOTONS, 16, 1024))


#: Photons before a candidate edge whose spacing gives the density there.
_LOCAL = 40
#: Spacings before the edge that give the gap to it.
_RIM = 8
#: A gap this many mean spacings wide is not within the light: the photon beyond it lies
#: outside (a constant density's exponential gap has a chance of 3e-7 to be this wide;
#: a density fading toward the edge, as a diffuser's, stretches its gaps a few times).
_WIDE_GAP = 15.0
#: Fewest photons the edge level would put beyond a candidate edge for its emptiness to
#: count (unless the candidate is at the face's own border).
_BEYOND = 3.0


def _change_point(v: np.ndarray, w: np.ndarray, a: float, b: float, end: float,
                  squared: bool, border: bool = False) -> tuple[float, float]:
    """(edge, its standard error) of light that ends going up ``v`` within ``a`` .. ``b``,
    the profile ending at ``end`` (``border``: the face's border, nothing lies beyond it).
    The edge follows the outermost photon that is still within the light: reached from the
    photons before it without a gap of :data:`_WIDE_GAP` mean spacings, and with less light
    beyond it (up to ``end``) than :data:`EDGE_LEVEL` of the density there (where that
    level would put at least :data:`_BEYOND` photons beyond). The edge lies one mean
    spacing of the last :data:`_RIM` photons past it (the gap to the edge of a Poisson
    sample is exponential, that spacing its mean and its spread; where the light fades to
    its edge the difference from the spacing before adds to the error); with no such
    photon, at the split of the photons into two runs of constant density (maximum
    likelihood). ``squared``: densities per unit of v^2 (a radius: area grows as r dr)."""
    g = (lambda t: t * t) if squared else (lambda t: t)
    outer = (v > b) & (v <= end)
    past = float(w[outer].sum())
    keep = (v >= a) & (v <= b)
    order = np.argsort(v[keep])
    vs, ws = v[keep][order], w[keep][order]
    if len(vs) <= _LOCAL:
        return b, b - a
    unit = ws.mean()
    ws = ws / unit  # photons, each weighted by its flux
    past /= unit
    gt = g(vs)
    cum = np.cumsum(ws)
    k = np.arange(_LOCAL, len(vs))
    # density before each candidate: of its last spacings (per photon) but the widest,
    # which may be the gap from the light's edge to a glow beyond it
    spacing = np.diff(gt) / ws[1:]
    window = np.lib.stride_tricks.sliding_window_view(spacing, _LOCAL - 1)[k - _LOCAL]
    rho = (_LOCAL - 2) / np.maximum(window.sum(axis=1) - window.max(axis=1), 1e-300)
    room = g(end) - gt[k]
    expected = EDGE_LEVEL * rho * room
    beyond = cum[-1] - cum[k] + past
    empty = (beyond <= expected) & ((expected >= _BEYOND) | border)
    # a wide gap with little light beyond the photon before it ends the light: a photon
    # past it is a glow's (a gap inside the light, a louvre's blade, has light beyond)
    wide = np.nonzero(((gt[k] - gt[k - 1]) * rho > _WIDE_GAP)[1:] & empty[:-1])[0]
    ok = np.nonzero(empty[:wide[0] + 1] if wide.size else empty)[0]
    if ok.size:
        i = int(k[ok[-1]])
        # the gap to the edge: the mean of the last few spacings, where the light may
        # already be fading (a diffuser's rim), but the widest
        last = np.diff(gt[i - _RIM:i + 1]) / ws[i - _RIM + 1:i + 1]
        density = (_RIM - 1) / max(float(last.sum() - last.max()), 1e-300)
        # where the light fades to its edge, how far the gap is from the one the photons
        # before it say: the uncertainty of placing an edge on a slope
        fade = abs(1.0 / density - 1.0 / float(rho[ok[-1]]))
    else:  # no clear step: the densest split into two runs (maximum likelihood)
        n_out = cum[-1] - cum
        with np.errstate(divide="ignore", invalid="ignore"):
            like = cum * np.log(cum / np.maximum(gt - g(a), 1e-300)) + np.where(
                n_out > 0, n_out * np.log(n_out / np.maximum(g(b) - gt, 1e-300)), 0.0)
        i = int(np.nanargmax(like))
        lo_i = max(0, i - _LOCAL)
        density = float((cum[i] - cum[lo_i]) / max(gt[i] - gt[lo_i], 1e-300))
        fade = 0.0
    gap = 1.0 / max(density, 1e-300)
    edge_g = min(gt[i] + gap, g(b))
    slope = 2.0 * vs[i] if squared else 1.0
    if slope <= 0:
        return float(vs[i]), float(b - a)
    return float(vs[i] + (edge_g - gt[i]) / slope), float(math.hypot(gap, fade) / slope)


def _edges(v: np.ndarray, w: np.ndarray, lo: float, hi: float,
           level: float = EDGE_LEVEL) -> tuple:
    """Where the light along ``v`` (within ``lo`` .. ``hi``) starts and ends: (start, end,
    their standard errors, and the bin-wide extent (start, end) that located them); bins
    below ``level`` of the typical one do not count."""
    n = _bins(len(v))
    h = _histogram(v, w, lo, hi, n)
    lit = h > 0
    if hi <= lo or not lit.any():  # a point (a box of no extent), or no light here
        return lo, hi, 0.0, 0.0, lo, hi
    above = np.nonzero(h >= level * _typical(h[lit], h[lit]))[0]
    d = (hi - lo) / n
    a0, b0 = lo + above[0] * d, lo + (above[-1] + 1) * d
    a, sa = _change_point(-v, w, -min(hi, a0 + 2 * d), -max(lo, a0 - 2 * d), -lo, False,
                          a0 - 2 * d <= lo)
    b, sb = _change_point(v, w, max(lo, b0 - 2 * d), min(hi, b0 + 2 * d), hi, False,
                          b0 + 2 * d >= hi)
    return -a, b, sa, sb, a0, b0


def _radial_edge(r: np.ndarray, w: np.ndarray, top: float, squared: bool = True
                 ) -> tuple[float, float]:
    """(edge, its standard error) of light that ends going out along ``r`` (0 .. ``top``):
    the last profile bin at the edge level (densities per unit of r^2 where ``squared``),
    the edge placed in it and the next by :func:`_change_point`."""
    n = _bins(len(r))
    bounds = np.linspace(0.0, top, n + 1)
    h = _histogram(r, w, 0.0, top, n)
    if not h.any():
        return top, top
    level = h / (np.diff(bounds ** 2) if squared else np.diff(bounds))
    lit = h > 0
    j = np.nonzero(level >= EDGE_LEVEL * _typical(level[lit], h[lit]))[0][-1]
    d = top / n
    return _change_point(r, w, max(0.0, bounds[j] - d), min(top, bounds[j + 1] + d), top,
                         squared)


def _round(x, y, w, cx, cy, ra, rb, circle: bool, iterations: int = 3) -> tuple:
    """A round opening's (length, width, centre, their errors, outside share). Its centre
    and shape: the edge along :data:`SECTORS` rays from the centre (in coordinates where
    the ellipse is a circle) and the ellipse through them (radius, ellipticity and centre
    by least squares, a ray whose edge lies more than 4 median deviations off left out;
    a ``circle`` has no ellipticity: one radius).
    Its size: the edge of all the light along the ellipse's radius (every ray's photons
    together); its error that edge's (or the fitted radius's where the rays scatter more)
    and the fitted ellipticity's."""
    if circle:
        ra = rb = 0.5 * (ra + rb)
    scale = ra / rb
    angle = -math.pi + (np.arange(SECTORS) + 0.5) * 2 * math.pi / SECTORS
    design = np.stack([np.ones(SECTORS), np.cos(2 * angle), np.cos(angle), np.sin(angle)],
                      axis=1)
    if circle:
        design[:, 1] = 0.0
    ellipticity_error = 0.0
    for _ in range(iterations):
        px, py = x - cx, (y - cy) * scale
        r, theta = np.hypot(px, py), np.arctan2(py, px)
        sector = np.floor((theta + math.pi) / (2 * math.pi) * SECTORS).astype(np.int64) \
            % SECTORS
        top = 1.25 * max(ra, 1e-12)
        edge = np.array([_radial_edge(r[sector == k], w[sector == k], top)[0]
                         for k in range(SECTORS)])
        use = np.ones(SECTORS, bool)
        for _ in range(4):
            p, *_ = np.linalg.lstsq(design[use], edge[use], rcond=None)
            resid = edge - design @ p
            spread = 1.4826 * float(np.median(np.abs(resid[use]))) + 1e-12 * top
            keep = np.abs(resid) <= 4.0 * spread
            if (keep == use).all() or keep.sum() < 8:
                break
            use = keep
        # the rays' scatter, of all of them (those left out too: how far an edge may be)
        scatter = float((resid ** 2).sum()) / max(SECTORS - (3 if circle else 4), 1)
        cov = np.linalg.pinv(design[use].T @ design[use]) * scatter
        ellipticity_error = math.sqrt(max(cov[1, 1], 0.0))
        radius_error = math.sqrt(max(cov[0, 0], 0.0))
        radius, ellipticity, dx, dy = p
        cx, cy = cx + dx, cy + dy / scale
        ra, rb = radius + ellipticity, (radius - ellipticity) / scale
        scale = ra / rb
    u = np.hypot((x - cx) / ra, (y - cy) / rb)
    ue, su = _radial_edge(u, w, 1.25)
    # the rim's own uncertainty: the all-light edge's, or the rays' scatter about their
    # ellipse where that says more (a rim that fades to its edge, a polygon's corners)
    su = max(su, radius_error / max(radius, 1e-12))
    ra, rb = ra * ue, rb * ue
    err_a = math.hypot(ra * su, ellipticity_error)
    err_b = math.hypot(rb * su, ellipticity_error / scale)
    inside = u <= ue * (1.0 + 1e-3)
    outside = 1.0 - float(w[inside].sum() / w.sum())
    return 2 * ra, 2 * rb, (cx, cy), (2 * err_a, 2 * err_b), outside


def flat_opening(q: np.ndarray, w: np.ndarray, lo, hi) -> dict:
    """The flat opening of the light crossing one face: ``q`` (N, 2) positions on it (m,
    its two in-face axes), ``w`` (N,) their flux, ``lo``, ``hi`` the face's extents. Keys:
    length, width (along the two axes), centre, round, error (length's, width's),
    outside (share of the light beyond the outline), rim (the exitance of the outline's
    outer tenth against its inside's, :func:`_rim_level`)."""
    x, y = q[:, 0], q[:, 1]
    a0, b0, sa0, sb0, c0, d0 = _edges(x, w, lo[0], hi[0])
    a1, b1, sa1, sb1, c1, d1 = _edges(y, w, lo[1], hi[1])
    # round or not, judged on the bin-wide extents (the edges found along C0 and C90 lie
    # inside a disc's, where its profile thins to nothing)
    within = (x >= c0) & (x <= d0) & (y >= c1) & (y <= d1)
    u = np.hypot((x - 0.5 * (c0 + d0)) / max(0.5 * (d0 - c0), 1e-12),
                 (y - 0.5 * (c1 + d1)) / max(0.5 * (d1 - c1), 1e-12))
    held = float(w[within].sum())
    round_ = held > 0 and float(w[within & (u > 1.0)].sum()) <= ROUND_OPENING_OUTSIDE * held
    if round_:
        start = (x, y, w, 0.5 * (c0 + d0), 0.5 * (c1 + d1), 0.5 * (d0 - c0), 0.5 * (d1 - c1))
        length, width, centre, error, outside = _round(*start, circle=False)
        # a circle unless its two axes differ by more than 3 errors and 0.5%
        if abs(length - width) <= max(3.0 * math.hypot(*error), 0.005 * (length + width)):
            length, width, centre, error, outside = _round(*start, circle=True)
        v = np.hypot((x - centre[0]) / max(0.5 * length, 1e-12),
                     (y - centre[1]) / max(0.5 * width, 1e-12))
        return {"length": length, "width": width, "centre": centre, "round": True,
                "error": error, "outside": outside, "rim": _rim_level(v, w)}
    tol = 1e-9 * max(hi[0] - lo[0], hi[1] - lo[1], 1e-12)
    inside = (x >= a0 - tol) & (x <= b0 + tol) & (y >= a1 - tol) & (y <= b1 + tol)
    v = np.maximum(np.abs(x - 0.5 * (a0 + b0)) / max(0.5 * (b0 - a0), 1e-12),
                   np.abs(y - 0.5 * (a1 + b1)) / max(0.5 * (b1 - a1), 1e-12))
    return {"length": b0 - a0, "width": b1 - a1, "centre": (0.5 * (a0 + b0), 0.5 * (a1 + b1)),
            "round": False, "error": (math.hypot(sa0, sb0), math.hypot(sa1, sb1)),
            "outside": 1.0 - float(w[inside].sum() / w.sum()), "rim": _rim_level(v, w)}


def _rim_level(v: np.ndarray, w: np.ndarray) -> float:
    """The exitance of the outline's outer tenth (``v`` 0.9 .. 1: the photons' scaled
    distance from the centre, 1 on the outline; areas as v^2) against its inside's."""
    core = float(w[v < 0.9].sum()) / 0.81
    band = float(w[(v >= 0.9) & (v <= 1.0)].sum()) / 0.19
    return band / core if core > 0 else 0.0


def opening_of_exits(positions: np.ndarray, flux: np.ndarray, lo, hi,
                     photons: int = 0) -> LuminousOpening:
    """The luminous opening of exit rays: ``positions`` (N, 3) where they cross the box
    ``lo``, ``hi`` (m, photometric frame), ``flux`` (N,) lm each; ``photons`` the photons
    traced for them (recorded)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    box = tuple(float(v) for v in hi - lo)
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    w = np.asarray(flux, np.float64).ravel()
    keep = np.isfinite(p).all(axis=1) & (w > 0)
    p, w = p[keep], w[keep]
    if not len(w):
        return LuminousOpening(0.0, 0.0, 0.0, tuple(0.5 * (lo + hi)), box=box, source="none",
                               note="no light leaves the luminaire", photons=photons)
    gap = np.abs(np.stack([p[:, 2] - lo[2], p[:, 2] - hi[2], p[:, 0] - lo[0],
                           p[:, 0] - hi[0], p[:, 1] - lo[1], p[:, 1] - hi[1]], axis=1))
    face = np.argmin(gap, axis=1)
    per_face = np.bincount(face, w, 6)
    f = 0 if per_face[0] >= per_face[1] else 1
    name = ("bottom", "top")[f]
    on = face == f
    level = float(lo[2] if f == 0 else hi[2])
    if not on.any():  # next to nothing leaves through top or bottom: the sides alone
        flat = {"length": 0.0, "width": 0.0, "centre": tuple(0.5 * (lo[:2] + hi[:2])),
                "round": False, "error": (0.0, 0.0), "outside": 0.0, "rim": 1.0}
    else:
        flat = flat_opening(p[on][:, :2], w[on], lo[:2], hi[:2])
    height, height_error = 0.0, 0.0
    sides = face >= 2
    if w[sides].sum() >= SIDE_SHARE * w.sum() and hi[2] > lo[2]:
        a, b, sa, sb, *_ = _edges(p[sides][:, 2], w[sides], lo[2], hi[2], HEIGHT_LEVEL)
        height, height_error = b - a, math.hypot(sa, sb)
    centre = (float(flat["centre"][0]), float(flat["centre"][1]), level)
    opening = LuminousOpening(float(flat["length"]), float(flat["width"]), float(height),
                              centre, bool(flat["round"]), box, "measured",
                              (float(flat["error"][0]), float(flat["error"][1]),
                               float(height_error)),
                              f"the light leaving the box's {name} face",
                              float(flat["outside"]), photons)
    why = None
    if not (opening.area > 0 or opening.height > 0):
        return replace(opening, length=0.0, width=0.0, height=0.0, error=(0.0, 0.0, 0.0),
                       round=False, source="none",
                       note="no luminous opening: the light leaves from a point or a line "
                            "(no luminous area); declare one with "
                            "lumitrace:luminousOpeningShape and lumitrace:luminousOpening")
    if flat["outside"] > STRAY_LIMIT:
        why = f"{flat['outside']:.1%} of it leaves outside its outline"
    elif flat["rim"] < RIM_LEVEL:
        why = (f"it fades out with no edge (its outline's outer tenth is {flat['rim']:.1%} "
               "as bright as its inside)")
    if why is not None:
        return replace(opening, length=0.0, width=0.0, height=0.0, error=(0.0, 0.0, 0.0),
                       round=False, source="none",
                       note=f"no luminous opening: the light leaves the box's {name} face "
                            f"({box[0]:.4g} x {box[1]:.4g} m) from everywhere: {why}; "
                            "declare one with lumitrace:luminousOpeningShape and "
                            "lumitrace:luminousOpening")
    return opening


def declared_opening(scene, centre=(0.0, 0.0, 0.0), box=(0.0, 0.0, 0.0)) -> LuminousOpening:
    """The opening the stage declares (``scene.declared_opening``), at ``centre``."""
    shape, (length, width, height) = scene.declared_opening
    return LuminousOpening(float(length), float(width), float(height), tuple(centre),
                           shape == "round", tuple(box), "declared",
                           note="declared on the stage (lumitrace:luminousOpening)")


def long_axis(opening: LuminousOpening) -> str:
    """The axis a linear luminaire is long along: "C0" or "C90" (its opening, or its box
    where no opening is meaningful, :data:`LINEAR_RATIO` times as long one way as the
    other), or "" (not linear)."""
    a, b = (opening.length, opening.width) if opening.meaningful else opening.box[:2]
    if a > 0 and b > 0:
        if a >= LINEAR_RATIO * b:
            return "C0"
        if b >= LINEAR_RATIO * a:
            return "C90"
    return ""


def opening_photons(photons: int) -> int:
    """Photons whose exits measure the opening of a run of ``photons``."""
    return int(min(OPENING_PHOTONS, max(photons, MIN_OPENING_PHOTONS)))


#: The openings last measured: (scene, seed, photons, opening); a scene is compared by
#: identity (a service makes a new one for every edit).
_MEASURED: list[tuple] = []
#: Where the photons leave the luminaire: ``escapes(scene, photons, seed)`` -> (positions
#: (N, 3, world m), directions, flux (N,)), the tracer's (it registers it when loaded:
#: the tracer reads photometry, not the other way round).
ESCAPES: list = []


def measured_opening(scene, photons: int, seed: int = 0) -> LuminousOpening:
    """The opening measured from the exits of ``photons`` photons of ``scene`` traced with
    ``seed`` (photon k of an emitter is photon k of the run with that seed)."""
    for s, sd, n, opening in _MEASURED:
        if s is scene and sd == seed and n == photons:
            return opening
    from ..film.goniometer import Goniometer

    if not ESCAPES:
        raise RuntimeError("the luminous opening is measured by tracing photons: load "
                           "lumitrace.trace first")
    g = Goniometer.of(scene)  # the box the tracer bins and these exits cross
    p, _, w = ESCAPES[0](scene, photons, seed)
    opening = opening_of_exits(np.asarray(p) @ np.asarray(g.axes, np.float64).T, w, g.lo,
                               g.hi, photons)
    _MEASURED[:] = [*_MEASURED[-1:], (scene, seed, photons, opening)]
    return opening


def luminous_opening(scene, photons: int, seed: int = 0) -> LuminousOpening:
    """The luminous opening of ``scene``: the one the stage declares (centred under its
    box), else the one measured from the exits of :func:`opening_photons` of a run of
    ``photons`` with ``seed``."""
    if scene.declared_opening:
        from ..film.goniometer import Goniometer

        g = Goniometer.of(scene)
        lo, hi = np.asarray(g.lo), np.asarray(g.hi)
        return declared_opening(scene, (float(0.5 * (lo[0] + hi[0])),
                                        float(0.5 * (lo[1] + hi[1])), float(lo[2])),
                                tuple(float(v) for v in hi - lo))
    return measured_opening(scene, opening_photons(photons), seed)
