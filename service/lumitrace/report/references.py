"""Closed-form reference distributions of the reference stages (``stages/reference/``).

Each reference stage stores its analytic expectation in its root layer's
``customLayerData["lumitrace:expectation"]`` (see :func:`read_expectation`). This module turns
such an expectation into numbers a traced result can be checked against:

- :func:`expected_intensity` gives the luminous intensity (cd) in given directions for the
  kinds whose whole distribution is known in closed form (``isotropic``, ``lambertian``,
  ``fresnel_slab``);
- :func:`expected_figures` gives scalar checks (lm, cd, degrees) for every kind, and is the
  only check for ``integrating_sphere`` and ``paraboloid``.

Everything is pure numpy. Directions are unit vectors in the stage's own axes; angles are
in radians unless a name ends in ``_deg``.
"""
from __future__ import annotations

import math
import os
from typing import Any, Mapping

import numpy as np

#: Key of the expectation dictionary in a reference stage's root-layer customLayerData.
EXPECTATION_KEY = "lumitrace:expectation"

#: Kinds with a full closed-form intensity distribution (see :func:`expected_intensity`).
DISTRIBUTION_KINDS = ("isotropic", "lambertian", "fresnel_slab", "mirror_cup")
#: All kinds of reference expectation.
KINDS = DISTRIBUTION_KINDS + ("integrating_sphere", "paraboloid")


# --------------------------------------------------------------------------------------
# Fresnel
# --------------------------------------------------------------------------------------
def fresnel_reflectance_sp(cos_i, n1: float, n2: float) -> tuple[np.ndarray, np.ndarray]:
    """Fresnel power reflectances (R_s, R_p) of a smooth interface between two dielectrics.

    Parameters
    ----------
    cos_i : array_like
        Cosine of the angle of incidence, measured from the surface normal on the side of
        medium ``n1`` (dimensionless; the sign is ignored).
    n1, n2 : float
        Refractive indices of the medium the light comes from and of the medium beyond
        the interface (dimensionless, > 0).

    Returns
    -------
    (R_s, R_p) : tuple of ndarray
        Reflectances (fractions of incident power, in [0, 1]) for light polarised
        perpendicular (s) and parallel (p) to the plane of incidence, with the broadcast
        shape of ``cos_i``. Both are 1 beyond the critical angle (total internal reflection)
        and at grazing incidence (unless ``n1 == n2``: no interface, no reflection).
    """
    if n1 <= 0 or n2 <= 0:
        raise ValueError(f"refractive indices must be positive, got n1={n1}, n2={n2}")
    ci = np.clip(np.abs(np.asarray(cos_i, dtype=np.float64)), 0.0, 1.0)
    if n1 == n2:  # no interface
        return np.zeros_like(ci), np.zeros_like(ci)
    sin2_t = (n1 / n2) ** 2 * (1.0 - ci * ci)
    tir = sin2_t >= 1.0
    ct = np.sqrt(np.clip(1.0 - sin2_t, 0.0, 1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (n1 * ci - n2 * ct) / (n1 * ci + n2 * ct)
        rp = (n2 * ci - n1 * ct) / (n2 * ci + n1 * ct)
    Rs = np.where(tir, 1.0, np.nan_to_num(rs * rs, nan=1.0))
    Rp = np.where(tir, 1.0, np.nan_to_num(rp * rp, nan=1.0))
    return Rs, Rp


def fresnel_unpolarised(cos_i, n1: float, n2: float) -> np.ndarray:
    """Fresnel reflectance of a smooth dielectric interface for unpolarised light.

    ``R = (R_s + R_p) / 2`` (fraction of incident power, dimensionless); see
    :func:`fresnel_reflectance_sp` for the parameters. At normal incidence
    ``R = ((n2 - n1) / (n2 + n1))**2``; beyond the critical angle ``R = 1``.
    """
    Rs, Rp = fresnel_reflectance_sp(cos_i, n1, n2)
    return 0.5 * (Rs + Rp)


def slab_transmittance(cos_gamma, n: float) -> np.ndarray:
    """Transmittance of a clear, non-absorbing plane-parallel slab in air, unpolarised light.

    The slab's inner reflections are summed incoherently (no thin-film interference). For
    each polarisation, with ``r`` the single-interface reflectance at the entry angle (the
    inner face reflects the same fraction), the slab transmits
    ``(1 - r)**2 * sum_k r**(2k) = (1 - r) / (1 + r)``; the result is the average of the s
    and p values. The slab reflects ``1 - T``; transmitted light leaves parallel to the
    incident direction.

    Parameters
    ----------
    cos_gamma : array_like
        Cosine of the angle of incidence in air (dimensionless; the sign is ignored).
    n : float
        Refractive index of the slab (dimensionless).

    Returns
    -------
    ndarray
        Transmittance in [0, 1] (fraction of incident luminous flux), shape of ``cos_gamma``.
        At normal incidence ``T = 2 n / (n**2 + 1)``; at grazing incidence ``T = 0``.
    """
    Rs, Rp = fresnel_reflectance_sp(cos_gamma, 1.0, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        ts = (1.0 - Rs) / (1.0 + Rs)
        tp = (1.0 - Rp) / (1.0 + Rp)
    return 0.5 * (ts + tp)


def lambertian_slab_flux(n: float, samples: int = 20001) -> tuple[float, float]:
    """Fractions of a Lambertian source's flux transmitted and reflected by a clear slab.

    ``T_L = int_0^{pi/2} T(gamma) 2 cos(gamma) sin(gamma) d gamma`` with
    :func:`slab_transmittance`, by Simpson quadrature in ``u = cos(gamma)**2``
    (``T_L = int_0^1 T(sqrt(u)) du``); the reflected fraction is ``1 - T_L``. Dimensionless.
    """
    if samples % 2 == 0:
        samples += 1
    u = np.linspace(0.0, 1.0, samples)
    f = slab_transmittance(np.sqrt(u), n)
    h = 1.0 / (samples - 1)
    t = h / 3.0 * (f[0] + f[-1] + 4.0 * f[1:-1:2].sum() + 2.0 * f[2:-1:2].sum())
    return float(t), float(1.0 - t)


# --------------------------------------------------------------------------------------
# Expectations
# --------------------------------------------------------------------------------------
def mirror_cup_reflections(radius: float, length: float, cos_gamma) -> np.ndarray:
    """Reflections k of a ray from a point on the axis of an open mirror cylinder (radius,
    length in one unit), at the rim plane, leaving at ``cos_gamma`` from the axis: it meets
    the wall first at depth radius / tan(gamma), then every 2 radius / tan(gamma), and the
    vertical wall keeps gamma."""
    c = np.clip(np.asarray(cos_gamma, np.float64), 1e-12, 1.0)
    tan = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
    reach = length * tan  # horizontal distance covered before the far end
    return np.where(reach <= radius, 0, 1 + np.floor((reach - radius) / (2.0 * radius)))


def mirror_cup_attenuation(expectation: Mapping[str, Any], cos_gamma) -> np.ndarray:
    """rho^k(gamma) of a mirror cup expectation (see :func:`mirror_cup_reflections`)."""
    k = mirror_cup_reflections(float(expectation["radius"]), float(expectation["length"]),
                               cos_gamma)
    return float(expectation["specular_reflectance"]) ** k


def mirror_cup_escaping_share(expectation: Mapping[str, Any], samples: int = 200001) -> float:
    """Share of a Lambertian source's flux that leaves the mirror cup: the integral of
    2 cos(gamma) sin(gamma) rho^k(gamma) over gamma < 90 deg (midpoint rule)."""
    g = (np.arange(samples) + 0.5) * (0.5 * math.pi / samples)
    w = 2.0 * np.cos(g) * np.sin(g) * mirror_cup_attenuation(expectation, np.cos(g))
    return float(w.sum() * (0.5 * math.pi / samples))


def _to_python(value: Any) -> Any:
    """Gf vectors, Vt arrays and nested dictionaries -> plain Python values."""
    if isinstance(value, (str, bool, int, float)):
        return value
    if isinstance(value, Mapping):
        return {str(k): _to_python(v) for k, v in value.items()}
    try:
        items = list(value)
    except TypeError:
        return value
    try:
        return [float(x) for x in items]
    except (TypeError, ValueError):
        return [_to_python(x) for x in items]


def read_expectation(stage_path: str | os.PathLike) -> dict:
    """Read the analytic expectation stored in a reference stage.

    Returns the root layer's ``customLayerData["lumitrace:expectation"]`` as a plain
    dictionary: numbers as float/int, vectors (``Gf.Vec3d``, ``double[]``) as lists of float,
    with at least ``kind`` (one of :data:`KINDS`), ``description`` and ``flux`` (lm).
    Only the root layer is read (no composition). Raises ``FileNotFoundError`` for a
    missing file and ``KeyError`` when the stage holds no expectation.
    """
    from pxr import Sdf

    path = os.fspath(stage_path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"{path}: no such stage")
    layer = Sdf.Layer.OpenAsAnonymous(path, metadataOnly=True)
    if layer is None:
        raise OSError(f"{path}: cannot be opened as a USD layer")
    data = dict(layer.customLayerData)
    if EXPECTATION_KEY not in data:
        raise KeyError(f"{path}: customLayerData has no {EXPECTATION_KEY!r}")
    return _to_python(data[EXPECTATION_KEY])


def _axis(expectation: Mapping[str, Any]) -> np.ndarray:
    axis = np.asarray(expectation.get("axis", (0.0, 0.0, -1.0)), dtype=np.float64)
    norm = np.linalg.norm(axis)
    if axis.shape != (3,) or not np.isfinite(norm) or norm == 0:
        raise ValueError(f"expectation axis must be a non-zero 3-vector, got {axis!r}")
    return axis / norm


def _peak(expectation: Mapping[str, Any]) -> float:
    if "peak_cd" in expectation:
        return float(expectation["peak_cd"])
    return float(expectation["flux"]) / math.pi


def expected_intensity(expectation: Mapping[str, Any], directions) -> np.ndarray:
    """Luminous intensity (cd) of a reference luminaire in the given far-field directions.

    Parameters
    ----------
    expectation : mapping
        An expectation dictionary (:func:`read_expectation`) of kind ``isotropic``
        (``flux``), ``lambertian`` (``flux``, ``axis``, optional ``peak_cd``) or
        ``fresnel_slab`` (``flux``, ``axis``, ``ior``, optional ``peak_cd``).
    directions : array_like, shape (N, 3)
        Directions in the stage's axes; normalised here (need not be unit length).

    Returns
    -------
    ndarray, shape (N,), float64
        Intensity in candela:

        - isotropic: ``flux / (4 pi)``;
        - lambertian: ``(flux / pi) cos(gamma)`` for ``gamma < 90 deg`` from ``axis``,
          0 beyond;
        - mirror_cup: ``(flux / pi) cos(gamma) rho^k(gamma)``, ``k`` the reflections on the
          way out (:func:`mirror_cup_reflections`);
        - fresnel_slab: ``(flux / pi) cos(gamma) T(gamma)`` on the ``axis`` side (transmitted)
          and ``(flux / pi) cos(gamma') (1 - T(gamma'))`` on the other (reflected; gamma'
          measured from ``-axis``), ``T`` = :func:`slab_transmittance`.

    Kinds ``integrating_sphere`` and ``paraboloid`` have no closed-form distribution: use
    :func:`expected_figures`.
    """
    kind = expectation.get("kind")
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"directions must have shape (N, 3), got {d.shape}")
    with np.errstate(divide="ignore", invalid="ignore"):
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
    if kind == "isotropic":
        return np.full(d.shape[0], float(expectation["flux"]) / (4.0 * math.pi))
    if kind == "lambertian":
        c = d @ _axis(expectation)
        return _peak(expectation) * np.clip(c, 0.0, None)
    if kind == "fresnel_slab":
        c = d @ _axis(expectation)
        n = float(expectation["ior"])
        a = np.abs(c)
        t = slab_transmittance(a, n)
        return _peak(expectation) * a * np.where(c > 0.0, t, 1.0 - t)
    if kind == "mirror_cup":
        c = d @ _axis(expectation)
        return _peak(expectation) * np.clip(c, 0.0, None) * mirror_cup_attenuation(
            expectation, c)
    if kind in KINDS:
        raise ValueError(f"expectation kind {kind!r} has no closed-form intensity "
                         "distribution; use expected_figures()")
    raise ValueError(f"unknown expectation kind {kind!r} (known: {', '.join(KINDS)})")


def expected_figures(expectation: Mapping[str, Any]) -> dict:
    """Scalar figures a traced result of a reference stage must reproduce.

    Recomputed from the expectation's inputs with the closed forms (not copied), so a
    stored figure that disagrees with its own inputs shows up in tests.
    Returns a dictionary (fluxes in lm, intensities in cd, angles in degrees) with
    ``escaped_flux`` (lm leaving the luminaire) for every kind, and:

    - isotropic: ``intensity_cd = flux / (4 pi)``;
    - lambertian: ``peak_cd = flux / pi``;
    - fresnel_slab: ``peak_cd``, ``transmitted_flux`` and ``reflected_flux`` (Lambertian
      source through the slab, see :func:`lambertian_slab_flux`), ``normal_transmittance``
      ``= 2 n / (n**2 + 1)``;
    - integrating_sphere: ``reflectance`` rho, ``port_fraction`` f (tessellated areas),
      ``sphere_multiplier = rho / (1 - rho (1 - f))``,
      ``escaped_flux = flux * rho * f / (1 - rho (1 - f))`` and ``escaped_flux_smooth``
      (the same with the smooth sphere's port fraction, when stored);
    - paraboloid: ``direct_cd = flux / (4 pi)`` (inside the opening, outside the beam),
      ``mirror_flux_fraction``, ``beam_flux = flux * fraction * specular_reflectance``,
      ``direct_flux = flux * (1 - fraction)``, ``escaped_flux = beam_flux + direct_flux``,
      ``beam_half_angle_deg`` and ``opening_half_angle_deg``.
    """
    kind = expectation.get("kind")
    flux = float(expectation["flux"])
    if kind == "isotropic":
        return {"escaped_flux": flux, "intensity_cd": flux / (4.0 * math.pi)}
    if kind == "lambertian":
        return {"escaped_flux": flux, "peak_cd": _peak(expectation)}
    if kind == "mirror_cup":
        return {"escaped_flux": flux * mirror_cup_escaping_share(expectation),
                "peak_cd": _peak(expectation)}
    if kind == "fresnel_slab":
        n = float(expectation["ior"])
        t, r = lambertian_slab_flux(n)
        return {"escaped_flux": flux, "peak_cd": _peak(expectation),
                "transmitted_flux": flux * t, "reflected_flux": flux * r,
                "normal_transmittance": 2.0 * n / (n * n + 1.0)}
    if kind == "integrating_sphere":
        rho = float(expectation["reflectance"])
        f = float(expectation["port_fraction"])
        out = {"reflectance": rho, "port_fraction": f,
               "sphere_multiplier": rho / (1.0 - rho * (1.0 - f)),
               "escaped_flux": flux * rho * f / (1.0 - rho * (1.0 - f))}
        if "port_fraction_smooth" in expectation:
            fs = float(expectation["port_fraction_smooth"])
            out["escaped_flux_smooth"] = flux * rho * fs / (1.0 - rho * (1.0 - fs))
        return out
    if kind == "paraboloid":
        frac = float(expectation["mirror_flux_fraction"])
        rho = float(expectation["specular_reflectance"])
        beam = flux * frac * rho
        direct = flux * (1.0 - frac)
        return {"direct_cd": flux / (4.0 * math.pi), "mirror_flux_fraction": frac,
                "beam_flux": beam, "direct_flux": direct, "escaped_flux": beam + direct,
                "beam_half_angle_deg": float(expectation["beam_half_angle_deg"]),
                "opening_half_angle_deg": float(expectation["opening_half_angle_deg"])}
    raise ValueError(f"unknown expectation kind {kind!r} (known: {', '.join(KINDS)})")
