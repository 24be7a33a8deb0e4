"""Photon emission from UsdLux lights: start points and directions in world metres.

Every light is a Lambertian emitter of its surface (UsdLux): disk and rect lights emit from
one side, along their local -Z; sphere lights from their whole surface (isotropic
intensity); cylinder lights from their side, not their caps. UsdLuxShapingAPI narrows the
emission about the local -Z axis: intensity is multiplied by ``cos(theta)**focus`` and by a
cone window that is 1 inside ``angle * (1 - softness)``, falls with a smoothstep to 0 at
``angle`` and is 0 beyond. The authored luminous flux is the flux after shaping.
"""
from __future__ import annotations

import numpy as np

from ..scene import Emitter
from ..scene.shaping import is_one_sided, is_shaped, profile_table
from . import rng
from .sampling import (cos_sin, cosine_hemisphere, normalize, to_world, uniform_cone,
                       uniform_disk)


def _shaped_directions(u1, u2, base_cos_power: int, e: Emitter) -> np.ndarray:
    """Local directions (3, N) about +z distributed as the shaped profile (table inversion)."""
    theta_tab, cdf = profile_table(base_cos_power, float(e.cone_angle), float(e.cone_softness),
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

    if is_one_sided(e.kind):
        if e.kind == "disk":
            p = uniform_disk(u1, u2, e.radius)
        else:
            p = np.stack([(u1 - 0.5) * e.width, (u2 - 0.5) * e.height, np.zeros(n)])
        axis = normal_map @ np.array([0.0, 0.0, -1.0])
        n_w = np.repeat((axis / np.linalg.norm(axis))[:, None], n, axis=1)
        local = _shaped_directions(u3, u4, 1, e) if is_shaped(e.kind, e.cone_angle, e.focus) else cosine_hemisphere(u3, u4)
        d = to_world(local, n_w)
        n_s = n_w
    elif e.kind == "sphere":
        if is_shaped(e.kind, e.cone_angle, e.focus):
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
