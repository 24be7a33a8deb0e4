"""Photon emission from UsdLux lights: start points and directions in world metres.

Every light is a Lambertian emitter of its surface (UsdLux): disk and rect lights emit from
one side, along their local -Z; sphere lights from their whole surface (isotropic
intensity); cylinder lights from their side, not their caps. UsdLuxShapingAPI narrows the
emission about the local -Z axis: intensity is multiplied by ``cos(theta)**focus`` and by a
cone window that is 1 inside ``angle * (1 - softness)``, falls with a smoothstep to 0 at
``angle`` and is 0 beyond. The authored luminous flux is the flux after shaping.
"""
from __future__ import annotations

import functools

import numpy as np

from . import rng
from .sampling import (cos_sin, cosine_hemisphere, normalize, to_world, uniform_cone,
                       uniform_disk)
from ..scene import Emitter

_PROFILE_SAMPLES = 4096


def is_shaped(e: Emitter) -> bool:
    """True when shaping changes the emission of ``e`` from the plain Lambertian one."""
    limit = 90.0 if e.kind in ("disk", "rect") else 180.0
    return e.focus > 0.0 or e.cone_angle < limit


def shaping_window(theta: np.ndarray, angle_deg: float, softness: float, focus: float) -> np.ndarray:
    """Relative intensity factor of the shaping at angles ``theta`` (rad) from the axis."""
    t_max = np.radians(angle_deg)
    t_in = t_max * (1.0 - np.clip(softness, 0.0, 1.0))
    w = np.where(theta <= t_max, 1.0, 0.0)
    if t_max > t_in:
        x = np.clip((t_max - theta) / (t_max - t_in), 0.0, 1.0)
        w = w * x * x * (3.0 - 2.0 * x)
    if focus > 0.0:
        w = w * np.maximum(np.cos(theta), 0.0) ** focus
    return w


@functools.lru_cache(maxsize=64)
def _profile_table(base_cos_power: int, angle_deg: float, softness: float, focus: float):
    """Inverse-CDF table over theta for intensity ``cos^base * window`` (rad)."""
    limit = np.pi / 2 if base_cos_power > 0 else np.pi
    t_hi = min(np.radians(angle_deg), limit)
    theta = np.linspace(0.0, t_hi, _PROFILE_SAMPLES + 1)
    f = shaping_window(theta, angle_deg, softness, focus) * np.sin(theta)
    if base_cos_power:
        f = f * np.maximum(np.cos(theta), 0.0) ** base_cos_power
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(theta))])
    if cdf[-1] <= 0.0:
        raise ValueError("shaping leaves no emission")
    return theta, cdf / cdf[-1]


def shaping_emits(kind: str, cone_angle: float, cone_softness: float, focus: float) -> bool:
    """Whether a light of ``kind`` shaped so still has directions to emit in, as the sampler
    resolves them (an extreme focus can leave none)."""
    try:
        _profile_table(1 if kind in ("disk", "rect") else 0, float(cone_angle),
                       float(cone_softness), float(focus))
    except ValueError:
        return False
    return True


def _shaped_directions(u1, u2, base_cos_power: int, e: Emitter) -> np.ndarray:
    """Local directions (3, N) about +z distributed as the shaped profile (table inversion)."""
    theta_tab, cdf = _profile_table(base_cos_power, float(e.cone_angle), float(e.cone_softness),
                                    float(e.focus))
    theta = np.interp(u1, cdf, theta_tab)
    c, s = cos_sin(2.0 * np.pi * u2)
    st = np.sin(theta)
    return np.stack([st * c, st * s, np.cos(theta)])


_MINUS_Z = np.array([[1.0], [-1.0], [-1.0]])


def emit(e: Emitter, key: np.uint64, index: np.ndarray, normals: bool = False):
    """Start points (3, N; world m) and unit directions (3, N; world) of photons ``index``.

    Uses the random dimensions of bounce 0, so photon i of an emitter always starts the same.
    With ``normals`` also the unit normals (3, N; world) of the emitting surface at the start
    points, on the side the photons leave (a point light's are its directions): the tracer
    offsets ray origins along them, so that a photon leaving at a grazing angle does not
    start inside a part the light touches.
    """
    u1, u2, u3, u4 = rng.uniforms(key, index, 0, 4)
    m = np.asarray(e.to_world, dtype=np.float64)
    lin, t = m[:3, :3], m[:3, 3:4]
    # normals transform with the inverse transpose; scaled first, so that a light in a stage
    # of tiny or huge units does not overflow (the reader refuses singular transforms)
    normal_map = np.linalg.inv(lin / np.abs(lin).max()).T
    n = index.shape[0]

    if e.kind in ("disk", "rect"):
        if e.kind == "disk":
            p = uniform_disk(u1, u2, e.radius)
        else:
            p = np.stack([(u1 - 0.5) * e.width, (u2 - 0.5) * e.height, np.zeros(n)])
        axis = normal_map @ np.array([0.0, 0.0, -1.0])
        n_w = np.repeat((axis / np.linalg.norm(axis))[:, None], n, axis=1)
        local = _shaped_directions(u3, u4, 1, e) if is_shaped(e) else cosine_hemisphere(u3, u4)
        d = to_world(local, n_w)
        n_s = n_w
    elif e.kind == "sphere":
        if is_shaped(e):
            w_local = _shaped_directions(u1, u2, 0, e) * _MINUS_Z
        else:
            w_local = uniform_cone(u1, u2, -1.0)
        d = normalize(lin @ w_local)
        if e.treat_as_point or e.radius == 0.0:
            p = np.zeros((3, n))
            n_s = d
        else:
            p = e.radius * to_world(cosine_hemisphere(u3, u4), w_local)
            n_s = normalize(normal_map @ p) if normals else None
    elif e.kind == "cylinder":
        c, s = cos_sin(2.0 * np.pi * u2)
        p = np.stack([(u1 - 0.5) * e.length, e.radius * c, e.radius * s])
        nl = np.stack([np.zeros(n), c, s])
        n_s = normalize(normal_map @ nl)
        d = to_world(cosine_hemisphere(u3, u4), n_s)
    else:
        raise ValueError(f"{e.path}: unknown emitter kind {e.kind!r}")
    if normals:
        return lin @ p + t, d, n_s
    return lin @ p + t, d
