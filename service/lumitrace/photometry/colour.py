"""Colour over angle: chromaticity, CCT and Duv of the light in every direction, and the
colour uniformity within the beam, from the goniophotometer's X, Y and Z.

Cells are C sectors by gamma zones of the goniophotometer (sums of its cells: unbiased),
and the colour of every direction all round (gamma zones over all C). Chromaticity is CIE
1976 u'v'; CCT and Duv are Ohno's (2013) method of colour-science, from CIE 1960 uv.
Uniformity is the largest distance in u'v' of a beam cell (intensity at least half the
peak cell's) from the beam's flux-weighted mean chromaticity, the Delta u'v' figure of
ANSI C78.377 and ENERGY STAR. Every value has its standard error from the two
independent halves of the photons; a maximum over noisy cells is biased upward by about
the cells' noise, which is stated beside it.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..film.accumulate import Accumulator
from ..film.goniometer import C_STEP, GAMMA_EDGES, N_C, cell_solid_angles
from ..scene import spectra

#: Cell size of the colour table (deg): C sectors and gamma zones.
COLOUR_C_STEP = 15.0
COLOUR_GAMMA_STEP = 5.0
#: A cell belongs to the beam from this share of the peak cell's intensity.
BEAM_SHARE = 0.5


def uv_prime(xyz: np.ndarray) -> np.ndarray:
    """CIE 1976 (u', v') (2, ...) of tristimulus values (3, ...); NaN where X+15Y+3Z is 0."""
    x, y, z = xyz
    d = x + 15.0 * y + 3.0 * z
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([np.where(d > 0, 4.0 * x / d, np.nan),
                         np.where(d > 0, 9.0 * y / d, np.nan)])


#: Farther than this from the Planckian locus (in CIE 1960 uv) a chromaticity has no
#: correlated colour temperature (CIE 015): its CCT is NaN, its Duv still given.
MAX_DUV = 0.05


def cct_duv(uvp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Correlated colour temperature (K) and Duv of chromaticities u'v' (2, ...) (Ohno
    2013, as colour-science computes it); NaN where undefined (CCT also beyond
    :data:`MAX_DUV`)."""
    shape = uvp.shape[1:]
    uv = np.stack([uvp[0], uvp[1] * (2.0 / 3.0)], axis=-1).reshape(-1, 2)
    out = np.full((len(uv), 2), np.nan)
    ok = np.isfinite(uv).all(axis=1)
    if ok.any():
        out[ok] = _ohno2013(uv[ok])
    out[~(np.abs(out[:, 1]) <= MAX_DUV), 0] = np.nan
    return out[:, 0].reshape(shape), out[:, 1].reshape(shape)


@functools.lru_cache(maxsize=1)
def _planckian_table() -> np.ndarray:
    """colour-science's Planckian table for Ohno's method, rows (T K, u, v): its defaults
    (CIE 1931 2 deg observer, 1000 to 100000 K in steps of about 0.1%), made once."""
    spectra.colour_science()  # imported quietly first
    from colour.colorimetry import handle_spectral_arguments
    from colour.temperature import ohno2013

    cmfs, _ = handle_spectral_arguments(None)
    return ohno2013.planckian_table(cmfs, ohno2013.CCT_MINIMAL_OHNO2013,
                                    ohno2013.CCT_MAXIMAL_OHNO2013,
                                    ohno2013.CCT_DEFAULT_SPACING_OHNO2013)


def _ohno2013(uv: np.ndarray) -> np.ndarray:
    """(CCT K, Duv) (N, 2) of CIE 1960 ``uv`` (N, 2): Ohno (2013) on colour-science's table
    and with its formulas, for all points at once (colour-science loops over points in
    Python: 0.3 ms a point, a third of a second for a colour table)."""
    table = _planckian_table()
    tu, tv = np.ascontiguousarray(table[:, 1]), np.ascontiguousarray(table[:, 2])
    nearest = np.empty(len(uv), np.int64)
    for s in range(0, len(uv), 64):  # (64, rows) distances at a time
        du = uv[s:s + 64, 0, None] - tu
        dv = uv[s:s + 64, 1, None] - tv
        nearest[s:s + 64] = np.argmin(np.sqrt(du * du + dv * dv), axis=1)
    rows = table[np.clip(nearest, 1, len(table) - 2)[:, None] + np.arange(-1, 2)]
    d = uv[:, None, :] - rows[..., 1:]
    dip, di, din = np.sqrt((d * d).sum(axis=-1)).T
    (tp, ti, tn), (up, _, un), (vp, _, vn) = rows[..., 0].T, rows[..., 1].T, rows[..., 2].T
    # triangular solution
    length = np.hypot(un - up, vn - vp)
    x = (dip ** 2 - din ** 2 + length ** 2) / (2 * length)
    t_t = tp + (tn - tp) * (x / length)
    sign = np.sign(uv[:, 1] - (vp + (vn - vp) * (x / length)))
    duv_t = (dip ** 2 - x ** 2) ** 0.5 * sign
    # parabolic solution, where the point is 0.002 or more off the locus
    big = (tn - ti) * (tp - tn) * (ti - tp)
    a = (tp * (din - di) + ti * (dip - din) + tn * (di - dip)) * big ** -1
    b = -(tp ** 2 * (din - di) + ti ** 2 * (dip - din) + tn ** 2 * (di - dip)) * big ** -1
    c = -(dip * (tn - ti) * ti * tn + di * (tp - tn) * tp * tn
          + din * (ti - tp) * tp * ti) * big ** -1
    t_p = -b / (2 * a)
    duv_p = (a * t_p ** 2 + b * t_p + c) * sign
    far = np.abs(duv_t) >= 0.002
    return np.stack([np.where(far, t_p, t_t), np.where(far, duv_p, duv_t)], axis=-1)


@dataclass(frozen=True)
class ColourOverAngle:
    """The colour of a result by direction.

    ``c``, ``gamma``: centres (deg) of the table's C sectors and gamma zones; ``xyz`` (3,
    C, G) mean X, Y, Z intensity (cd) of every cell; ``uv`` (2, C, G) its u'v', ``sigma``
    (C, G) the standard error of that point (u'v' units), ``cct`` (K) and ``duv``. The
    ``ring_*`` arrays are the same over all C (gamma zones all round). ``mean_uv`` is the
    beam's flux-weighted chromaticity, ``uniformity`` the largest Delta u'v' of a beam cell
    from it, ``noise`` the RMS standard error of the beam cells' u'v', ``beam_cells`` how
    many cells the beam has; ``total`` the u'v', CCT and Duv of all the light.
    """

    c: np.ndarray
    gamma: np.ndarray
    xyz: np.ndarray
    uv: np.ndarray
    sigma: np.ndarray
    cct: np.ndarray
    duv: np.ndarray
    ring_xyz: np.ndarray
    ring_uv: np.ndarray
    ring_sigma: np.ndarray
    ring_cct: np.ndarray
    ring_duv: np.ndarray
    mean_uv: tuple[float, float]
    uniformity: float
    noise: float
    beam_cells: int
    total: dict

    def as_dict(self) -> dict:
        """The figures for the summary, ``--json`` and the result record."""
        return {"cct_K": self.total["cct_K"], "duv": self.total["duv"],
                "chromaticity_uv": self.total["uv"],
                "colour_uniformity_duv": self.uniformity,
                "colour_uniformity_noise": self.noise}

    def table(self) -> dict:
        """The table of colour over angle as JSON-ready lists (undefined values null)."""
        return {
            "definition": "cells are C sectors by gamma zones (centres given); xyz is the "
                          "mean X, Y, Z intensity (cd) of a cell, u'v' CIE 1976, cct and "
                          "duv by Ohno 2013; sigma is the standard error of a cell's u'v' "
                          "point from two independent halves of the photons; uniformity "
                          f"is the largest Delta u'v' of a cell of at least {BEAM_SHARE:.0%} "
                          "of the peak cell's intensity from their flux-weighted mean",
            "units": {"c": "deg", "gamma": "deg", "X": "cd", "Y": "cd", "Z": "cd",
                      "cct": "K"},
            "c": self.c.tolist(), "gamma": self.gamma.tolist(),
            "X": _json(self.xyz[0]), "Y": _json(self.xyz[1]), "Z": _json(self.xyz[2]),
            "u'": _json(self.uv[0]), "v'": _json(self.uv[1]), "sigma": _json(self.sigma),
            "cct": _json(self.cct), "duv": _json(self.duv),
            "allRound": {"Y": _json(self.ring_xyz[1]), "u'": _json(self.ring_uv[0]),
                         "v'": _json(self.ring_uv[1]), "sigma": _json(self.ring_sigma),
                         "cct": _json(self.ring_cct), "duv": _json(self.ring_duv)},
            "beam": {"meanUV": _json(self.mean_uv), "uniformityDuv": _json(self.uniformity),
                     "noise": _json(self.noise), "cells": self.beam_cells},
            "total": {k: _json(v) for k, v in self.total.items()},
        }


def _json(values):
    """Numbers (any shape) rounded to 6 decimals as JSON-ready lists, NaN as None."""
    a = np.round(np.asarray(values, np.float64), 6)
    return np.where(np.isfinite(a), a, None).tolist()


def _cell_groups(c_step: float, gamma_step: float) -> tuple[np.ndarray, int, int]:
    """The table cell of every goniophotometer cell (N_CELLS,), and the table's size."""
    n_c = int(round(360.0 / c_step))
    n_g = int(round(180.0 / gamma_step))
    g_mid = 0.5 * (GAMMA_EDGES[1:] + GAMMA_EDGES[:-1])
    c_mid = (np.arange(N_C) + 0.5) * C_STEP
    gi = np.minimum((g_mid // gamma_step).astype(np.int64), n_g - 1)
    ci = np.minimum((c_mid // c_step).astype(np.int64), n_c - 1)
    return (ci[:, None] * n_g + gi[None, :]).ravel(), n_c, n_g


def colour_over_angle(acc: Accumulator, c_step: float = COLOUR_C_STEP,
                      gamma_step: float = COLOUR_GAMMA_STEP) -> ColourOverAngle | None:
    """The colour over angle of a result, or None where the scene has no colour."""
    if acc.colour == "none":
        return None
    groups, n_c, n_g = _cell_groups(c_step, gamma_step)
    omega = np.bincount(groups, weights=cell_solid_angles().ravel(), minlength=n_c * n_g)

    def table(xyz_cells):  # flux per table cell (3, n_c * n_g)
        return np.stack([np.bincount(groups, weights=v, minlength=n_c * n_g) for v in xyz_cells])

    flux = table(acc.cell_tristimulus())
    halves = [table(acc.cell_tristimulus(h)) for h in (0, 1)]
    ring = lambda f: f.reshape(3, n_c, n_g).sum(axis=1)  # noqa: E731
    ring_omega = omega.reshape(n_c, n_g).sum(axis=0)

    def colour_of(f, fa, fb, om):
        uv = uv_prime(f)
        sigma = 0.5 * np.hypot(*(uv_prime(fa) - uv_prime(fb)))
        cct, duv = cct_duv(uv)
        return f / om, uv, sigma, cct, duv

    xyz, uv, sigma, cct, duv = colour_of(flux, *halves, omega)
    r_xyz, r_uv, r_sigma, r_cct, r_duv = colour_of(ring(flux), *map(ring, halves), ring_omega)

    intensity = xyz[1]
    beam = intensity >= BEAM_SHARE * intensity.max() if intensity.max() > 0 else \
        np.zeros_like(intensity, bool)
    beam &= np.isfinite(uv).all(axis=0)
    if beam.any():
        w = flux[1][beam]
        mean = (uv[:, beam] * w).sum(axis=1) / w.sum()
        spread = float(np.hypot(*(uv[:, beam] - mean[:, None])).max())
        noise = float(np.sqrt(np.nanmean(sigma[beam] ** 2)))
    else:
        mean, spread, noise = np.array([np.nan, np.nan]), float("nan"), float("nan")
    total_uv = uv_prime(flux.sum(axis=1))
    t_cct, t_duv = cct_duv(total_uv)
    shape = (n_c, n_g)
    return ColourOverAngle(
        c=(np.arange(n_c) + 0.5) * c_step, gamma=(np.arange(n_g) + 0.5) * gamma_step,
        xyz=xyz.reshape(3, *shape), uv=uv.reshape(2, *shape), sigma=sigma.reshape(shape),
        cct=cct.reshape(shape), duv=duv.reshape(shape), ring_xyz=r_xyz, ring_uv=r_uv,
        ring_sigma=r_sigma, ring_cct=r_cct, ring_duv=r_duv,
        mean_uv=(float(mean[0]), float(mean[1])), uniformity=spread, noise=noise,
        beam_cells=int(beam.sum()),
        total={"uv": [float(total_uv[0]), float(total_uv[1])], "cct_K": float(t_cct),
               "duv": float(t_duv)})
