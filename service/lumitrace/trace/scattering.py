"""Photon scattering at surfaces, vectorised per scattering model.

Scattering is analog: a photon keeps its flux and survives with the probability of the
material's albedo (Russian roulette with the albedo as survival probability, which is
unbiased and keeps every photon of an emitter at the same weight). Surfaces are two-sided
except for dielectrics, whose front side (counter-clockwise winding) faces the air.

Each photon carries a linear polarisation direction (unit vector across its direction).
Light from the sources and from diffuse surfaces is unpolarised (a random direction per
photon); dielectric and specular surfaces reflect and transmit the s and p components with
their own Fresnel amplitudes. Without it a clear slab would transmit too little at oblique
angles: (1 - F)/(1 + F) of the mean F instead of the mean of (1 - R_s)/(1 + R_s) and
(1 - R_p)/(1 + R_p), several percent at 60 degrees.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sampling import cos_sin, cosine_about, cross, dot, orthonormal_basis, reflect
from ..scene import (ABSORBER, DIELECTRIC, DIFFUSE, GLOSSY, MIRROR, SCATTERING_MODELS,
                    TRANSLUCENT, Material)

SCATTERING_CODES = range(len(SCATTERING_MODELS))


@dataclass(frozen=True)
class MaterialTable:
    """Per-material parameters as arrays indexed by material number (M,)."""

    kind: np.ndarray
    reflectance: np.ndarray
    specular: np.ndarray
    transmittance: np.ndarray
    ior: np.ndarray
    alpha: np.ndarray

    @classmethod
    def from_materials(cls, materials: tuple[Material, ...]) -> "MaterialTable":
        f = lambda name: np.array([getattr(m, name) for m in materials], dtype=np.float64)  # noqa: E731
        return cls(kind=np.array([m.kind for m in materials], dtype=np.int8),
                   reflectance=f("reflectance"), specular=f("specular_reflectance"),
                   transmittance=f("transmittance"), ior=f("ior"),
                   alpha=np.maximum(f("roughness") ** 2, 1e-4))


def fresnel_amplitudes(cos_i: np.ndarray, eta: np.ndarray):
    """Fresnel amplitude coefficients (r_s, r_p, t_s, t_p) and cos(theta_t).

    ``eta = n1 / n2`` is the relative index, ``cos_i`` > 0 the cosine of incidence; the p
    directions are ``s x d`` of each wave. Total internal reflection gives |r| = 1, t = 0.
    """
    sin2_t = eta * eta * np.maximum(0.0, 1.0 - cos_i * cos_i)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    a = eta * cos_i
    b = eta * cos_t
    rs = np.where(tir, -1.0, (a - cos_t) / (a + cos_t))
    rp = np.where(tir, 1.0, (cos_i - b) / (cos_i + b))
    ts = np.where(tir, 0.0, 2.0 * a / (a + cos_t))
    tp = np.where(tir, 0.0, 2.0 * a / (cos_i + b))
    return rs, rp, ts, tp, cos_t


def fresnel_dielectric(cos_i: np.ndarray, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unpolarised Fresnel reflectance and cos(theta_t) for relative index ``eta = n1/n2``."""
    rs, rp, _, _, cos_t = fresnel_amplitudes(cos_i, eta)
    return 0.5 * (rs * rs + rp * rp), cos_t


def _s_p_basis(d: np.ndarray, n: np.ndarray, pol: np.ndarray):
    """The s direction of the plane of incidence of ``d`` on ``n`` (3, N) and the s and p
    components (cos phi, sin phi) of the polarisation ``pol``. At normal incidence s is
    taken along ``pol`` (s and p behave alike there)."""
    s = cross(d, n)
    ls = np.sqrt(dot(s, s))
    s = np.where(ls > 1e-12, s / np.maximum(ls, 1e-300), pol)
    p = cross(s, d)
    return s, dot(pol, s), dot(pol, p)


def _polarise(s, c, sn, amp_s, amp_p, d_out, fallback):
    """Polarisation of an outgoing wave along ``d_out`` with s and p amplitudes."""
    e = (amp_s * c) * s + (amp_p * sn) * cross(s, d_out)
    le = np.sqrt(dot(e, e))
    return np.where(le > 1e-12, e / np.maximum(le, 1e-300), fallback)


#: Marks an unpolarised photon in a polarisation array (NaN in the first component).
UNPOLARISED = np.nan


def _polarisation(pol: np.ndarray, d: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``pol`` with unpolarised photons given a random linear polarisation (drawn from
    ``u``): drawing it only where a surface depends on it keeps diffuse paths cheap."""
    need = np.isnan(pol[0])
    if need.any():
        pol = pol.copy()
        pol[:, need] = random_polarisation(d[:, need], u[need])
    return pol


def random_polarisation(d: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Unpolarised light: a uniformly random unit direction across each ``d`` (3, N)."""
    t, b = orthonormal_basis(d)
    c, s = cos_sin(np.pi * u)
    return c * t + s * b


def smith_g1(cos_theta: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith masking G1 for the GGX distribution at ``cos_theta`` (0 below the surface)."""
    c2 = np.clip(cos_theta * cos_theta, 1e-300, 1.0)
    tan2 = (1.0 - c2) / c2
    return np.where(cos_theta > 0.0, 2.0 / (1.0 + np.sqrt(1.0 + alpha * alpha * tan2)), 0.0)


def sample_ggx_vndf(wi: np.ndarray, alpha: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """GGX microfacet normals (local frame, z up, (3, N)) distributed as the visible normals
    seen from ``wi`` (Heitz 2018, "Sampling the GGX distribution of visible normals")."""
    vh = np.stack([alpha * wi[0], alpha * wi[1], wi[2]])
    vh /= np.sqrt(dot(vh, vh))
    lensq = vh[0] * vh[0] + vh[1] * vh[1]
    ok = lensq > 0
    inv = np.where(ok, 1.0 / np.sqrt(np.maximum(lensq, 1e-300)), 0.0)
    t1 = np.stack([np.where(ok, -vh[1] * inv, 1.0), np.where(ok, vh[0] * inv, 0.0),
                   np.zeros_like(lensq)])
    t2 = cross(vh, t1)
    r = np.sqrt(u1)
    c, s_ = cos_sin(2.0 * np.pi * u2)
    p1 = r * c
    s = 0.5 * (1.0 + vh[2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * r * s_
    p3 = np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))
    nh = p1 * t1 + p2 * t2 + p3 * vh
    ne = np.stack([alpha * nh[0], alpha * nh[1], np.maximum(nh[2], 1e-12)])
    return ne / np.sqrt(dot(ne, ne))


def kind_runs(kind: np.ndarray) -> list[tuple[int, int, int]]:
    """(model, start, stop) runs of an array of scattering-model codes sorted ascending."""
    counts = np.bincount(kind, minlength=len(SCATTERING_CODES))
    ends = np.cumsum(counts)
    return [(k, int(ends[k] - counts[k]), int(ends[k])) for k in np.flatnonzero(counts)]


def scatter(table: MaterialTable, mat: np.ndarray, d: np.ndarray, ng: np.ndarray,
            u: list[np.ndarray], pol: np.ndarray,
            runs: list[tuple[int, int, int]] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """New directions (3, N), survival flags (N,) and polarisations (3, N) of photons
    arriving along ``d`` with polarisation ``pol`` at surfaces with unit geometric normals
    ``ng`` and material numbers ``mat``. ``u`` holds four uniform arrays (this bounce's).

    ``pol`` may be None where the scene has no dielectric, the one model whose response
    depends on polarisation: then nothing is spent on tracking it.
    ``runs`` (from :func:`kind_runs`) says the photons are already grouped by scattering
    model, as the tracer arranges, so every model works on slices; without it they are
    grouped here and put back in their order afterwards.
    """
    if runs is None:
        kind = np.take(table.kind, mat)
        order = np.argsort(kind, kind="stable")
        if np.any(order != np.arange(order.size)):
            take = lambda a: np.take(a, order, axis=-1)  # noqa: E731
            o, a, p = scatter(table, take(mat), take(d), take(ng), [take(x) for x in u],
                              None if pol is None else take(pol), kind_runs(take(kind)))
            inv = np.empty_like(order)
            inv[order] = np.arange(order.size)
            return (np.take(o, inv, axis=1), np.take(a, inv),
                    None if p is None else np.take(p, inv, axis=1))
        runs = kind_runs(kind)
    cos_d = dot(d, ng)
    front = cos_d < 0.0
    nf = ng * np.where(front, 1.0, -1.0)  # normal on the side the photon comes from
    if len(runs) == 1:
        return _scatter_kind(table, runs[0][0], mat, d, nf, ng, cos_d, front, u, pol)
    out = np.empty_like(d)
    pol_out = None if pol is None else np.empty_like(d)
    alive = np.empty(d.shape[1], dtype=bool)
    for k, a, b in runs:
        o, al, p = _scatter_kind(table, k, mat[a:b], d[:, a:b], nf[:, a:b], ng[:, a:b],
                                 cos_d[a:b], front[a:b], [x[a:b] for x in u],
                                 None if pol is None else pol[:, a:b])
        out[:, a:b], alive[a:b] = o, al
        if pol is not None:
            pol_out[:, a:b] = p
    return out, alive, pol_out


def _scatter_kind(table, k, m, d, nf, ng, cos_d, front, u, pol):
    """:func:`scatter` for photons that all hit surfaces of scattering model ``k``."""
    u0, u1, u2, u3 = u
    unpolarised = None if pol is None else np.full_like(d, UNPOLARISED)
    if k == DIFFUSE:
        return cosine_about(nf, u1, u2), u0 < np.take(table.reflectance, m), unpolarised
    if k == TRANSLUCENT:
        r = np.take(table.reflectance, m)
        side = np.where(u0 < r, 1.0, -1.0)
        return (cosine_about(nf * side, u1, u2), u0 < r + np.take(table.transmittance, m),
                unpolarised)
    if k == MIRROR:
        out = reflect(d, ng)
        if pol is not None:
            pol = _metal_polarisation(d, ng, _polarisation(pol, d, u3), out)
        return out, u0 < np.take(table.specular, m), pol
    if k == GLOSSY:
        t, b = orthonormal_basis(nf)
        wi = np.stack([-dot(d, t), -dot(d, b), np.maximum(-dot(d, nf), 1e-9)])
        alpha = np.take(table.alpha, m)
        h = sample_ggx_vndf(wi, alpha, u1, u2)
        wo = (2.0 * dot(wi, h)) * h - wi
        survive = np.take(table.specular, m) * smith_g1(wo[2], alpha)
        out = wo[0] * t + wo[1] * b + wo[2] * nf
        if pol is not None:
            hw = h[0] * t + h[1] * b + h[2] * nf
            pol = _metal_polarisation(d, hw, _polarisation(pol, d, u3), out)
        return out, (u0 < survive) & (wo[2] > 0.0), pol
    if k == DIELECTRIC:
        ior = np.take(table.ior, m)
        eta = np.where(front, 1.0 / ior, ior)
        cos_i = np.abs(cos_d)
        rs, rp, ts, tp, cos_t = fresnel_amplitudes(cos_i, eta)
        pin = _polarisation(np.full_like(d, UNPOLARISED) if pol is None else pol, d, u3)
        sv, c, sn = _s_p_basis(d, nf, pin)
        refl = u0 < rs * rs * c * c + rp * rp * sn * sn
        d_t = eta * d + (eta * cos_i - cos_t) * nf
        out = np.where(refl, reflect(d, nf), d_t)
        pol = _polarise(sv, c, sn, np.where(refl, rs, ts), np.where(refl, rp, tp), out, pin)
        return out, np.ones(d.shape[1], dtype=bool), pol
    if k == ABSORBER:
        return d, np.zeros(d.shape[1], dtype=bool), pol
    raise ValueError(f"unknown scattering model {k}")  # pragma: no cover - validated on read


def _metal_polarisation(d, n, pol, d_out):
    """Polarisation after an ideal metallic reflection (r_s = -1, r_p = 1) about ``n``."""
    sv, c, sn = _s_p_basis(d, n, pol)
    one = np.ones_like(c)
    return _polarise(sv, c, sn, -one, one, d_out, pol)
