"""The BUG rating (backlight, uplight, glare) of IES TM-15-11 and its addendum A, from the
zonal lumens of the goniophotometer's exact photon counts, each with its standard error.

Zones by gamma from nadir: low 0-30, mid 30-60, high 60-80, very high 80-90 deg, forward
(C within 90 deg of the forward direction: C0 by default, TM-15's 270 to 90 deg; C90 for a
roadway luminaire photometered with C0 along the road, as IES files of street lights are)
and back; uplight low 90-100 and high 100-180 deg. Their edges are goniometer cell edges, so the zones are sums of whole cells:
exact photon counts, not integrals of a resampled grid, with the binomial variance of
analog photons. The ratings are the addendum's tables (lumens, asymmetric types I to IV);
a rating that a zone moved by two standard errors would change is shown as a range.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..film.accumulate import Accumulator
from ..film.goniometer import C_STEP, GAMMA_EDGES, N_C, N_CELLS, N_GAMMA
from ..table_cache import kept_table

ZONES = ("FL", "FM", "FH", "FVH", "BL", "BM", "BH", "BVH", "UL", "UH")
#: Gamma edges (deg) of the forward and back zones, and of the uplight zones.
DOWN_EDGES = (0.0, 30.0, 60.0, 80.0, 90.0)
UP_EDGES = (90.0, 100.0, 180.0)
#: Addendum A's largest zone lumens for ratings 0 to 4 (above the last: 5).
BACKLIGHT = {"BH": (110, 500, 1000, 2500, 5000), "BM": (220, 1000, 2500, 5000, 8500),
             "BL": (110, 500, 1000, 2500, 5000)}
UPLIGHT = {"UH": (0, 10, 50, 500, 1000), "UL": (0, 10, 50, 500, 1000)}
GLARE = {"FVH": (10, 100, 225, 500, 750), "BVH": (10, 100, 225, 500, 750),
         "FH": (660, 1800, 5000, 7500, 12000), "BH": (110, 500, 1000, 2500, 5000)}
#: Standard errors a zone is moved by for the rating's range.
RANGE_SIGMAS = 2.0
#: The forward directions a rating may take (the C plane the luminaire faces), in deg.
FORWARD = {"C0": 0.0, "C90": 90.0, "C180": 180.0, "C270": 270.0}


@kept_table
def zone_of_cell() -> np.ndarray:
    """The zone (index into :data:`ZONES`) of every goniometer cell (C-major)."""
    centres = (np.arange(N_C) + 0.5) * C_STEP
    forward = np.cos(np.radians(centres)) > 0.0
    g = 0.5 * (GAMMA_EDGES[1:] + GAMMA_EDGES[:-1])
    down = np.searchsorted(DOWN_EDGES, g) - 1  # 0..3 below the horizon
    up = 8 + np.searchsorted(UP_EDGES, g) - 1
    zone = np.where(g < 90.0, down[None, :] + np.where(forward, 0, 4)[:, None], up[None, :])
    return zone.astype(np.int64).ravel()


@functools.lru_cache(maxsize=4)
def zones(forward: str = "C0") -> np.ndarray:
    """The zone of every goniometer cell (C-major) with ``forward`` (a key of
    :data:`FORWARD`) the forward direction: C0's zones turned with it."""
    shift = int(round(FORWARD[forward] / C_STEP))
    turned = np.roll(zone_of_cell().reshape(N_C, N_GAMMA), shift, axis=0).ravel()
    turned.setflags(write=False)
    return turned


@functools.lru_cache(maxsize=4)
def _zone_rows(forward: str = "C0") -> tuple[np.ndarray, np.ndarray]:
    """Which C planes are forward (N_C,), and the zone of each gamma cell (2, N_GAMMA) on
    the forward planes and on the back ones: a cell's zone depends on its side and gamma
    alone."""
    zone = zones(forward).reshape(N_C, N_GAMMA)
    forward = np.isin(zone, (0, 1, 2, 3)).any(axis=1)
    return forward, np.stack([zone[np.argmax(forward)], zone[np.argmin(forward)]])


def zone_lumens(acc: Accumulator, forward: str = "C0") -> tuple[np.ndarray, np.ndarray]:
    """Lumens in each of :data:`ZONES` (``forward`` the forward direction) and their
    standard errors: per emitter, a zone's count is binomial, var = sum w^2 n (1 - n / N)."""
    zone = zones(forward)
    forward, zone_rows = _zone_rows(forward)
    flux, var = np.zeros(len(ZONES)), np.zeros(len(ZONES))
    for w, total, values, idx in acc.emitter_cells():
        if idx is None:  # the C planes of each side summed first: exact integer counts
            planes = values[:N_CELLS].reshape(N_C, N_GAMMA)
            sides = np.stack([planes[forward].sum(axis=0), planes[~forward].sum(axis=0)])
            n = np.bincount(zone_rows.ravel(), weights=sides.ravel().astype(np.float64),
                            minlength=len(ZONES))
        else:
            keep = idx < N_CELLS
            n = np.bincount(zone[idx[keep]], weights=values[keep].astype(np.float64),
                            minlength=len(ZONES))
        flux += w * n
        var += w * w * n * np.maximum(1.0 - n / total, 0.0)
    return flux, np.sqrt(var)


def _rating(zones: dict[str, float], table: dict[str, tuple]) -> int:
    """The lowest rating whose limits every zone of ``table`` keeps."""
    for r in range(5):
        if all(zones[z] <= limits[r] for z, limits in table.items()):
            return r
    return 5


@dataclass(frozen=True)
class BugRating:
    """Ratings (0-5) and zone lumens (lm) with standard errors."""

    b: int
    u: int
    g: int
    lumens: dict
    errors: dict
    low: tuple[int, int, int]   # ratings with every zone two standard errors lower
    high: tuple[int, int, int]  # and higher
    forward: str = "C0"         # the forward direction (a key of FORWARD)

    @property
    def text(self) -> str:
        return f"B{self.b} U{self.u} G{self.g}"

    @property
    def range_text(self) -> str:
        """The rating, a letter whose zones are within two standard errors of a limit
        shown as a range (B1-2)."""
        parts = []
        for name, lo, hi in zip("BUG", self.low, self.high):
            parts.append(f"{name}{lo}" if lo == hi else f"{name}{lo}-{hi}")
        return " ".join(parts)

    def as_dict(self) -> dict:
        return {"bug_rating": self.text, "bug_rating_range": self.range_text,
                "bug_zone_lumens": dict(self.lumens), "bug_zone_lumens_error": dict(self.errors),
                "bug_forward": self.forward}


def ratings(zones: dict[str, float]) -> tuple[int, int, int]:
    """(B, U, G) of zone lumens."""
    return _rating(zones, BACKLIGHT), _rating(zones, UPLIGHT), _rating(zones, GLARE)


def bug_rating(acc: Accumulator, forward: str = "C0") -> BugRating:
    """The BUG rating of the counts in ``acc``, ``forward`` (C0, C90, C180 or C270) the
    direction the luminaire faces."""
    if forward not in FORWARD:
        raise ValueError(f"the forward direction must be one of {', '.join(FORWARD)}, "
                         f"got {forward!r}")
    flux, err = zone_lumens(acc, forward)
    lumens = {z: float(f) for z, f in zip(ZONES, flux)}
    errors = {z: float(e) for z, e in zip(ZONES, err)}
    b, u, g = ratings(lumens)
    # a zone with no photons is exactly empty: its error does not lift it off zero
    lo = ratings({z: max(lumens[z] - RANGE_SIGMAS * errors[z], 0.0) for z in ZONES})
    hi = ratings({z: lumens[z] + RANGE_SIGMAS * errors[z] for z in ZONES})
    return BugRating(b, u, g, lumens, errors, lo, hi, forward)



def facing(scene, forward: str | None):
    """``scene`` with the BUG rating's forward direction ``forward`` (a key of
    :data:`FORWARD`; None: as the stage says, ``lumitrace:bugForward``)."""
    if forward is None or forward == scene.info.bug_forward:
        return scene
    if forward not in FORWARD:
        raise ValueError(f"the forward direction must be one of {', '.join(FORWARD)}, "
                         f"got {forward!r}")
    from dataclasses import replace

    return replace(scene, info=replace(scene.info, bug_forward=forward))
