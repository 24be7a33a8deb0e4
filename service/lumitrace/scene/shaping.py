"""How a UsdLux light's emission is shaped: one-sided lights and the UsdLuxShapingAPI window.

Disk and rect lights are one-sided Lambertian emitters along their local -Z; sphere lights
emit uniformly in direction; cylinder lights are not shaped. UsdLuxShapingAPI multiplies
the intensity at angle theta from the emission axis by ``cos(theta)**focus`` and by a cone
window that is 1 up to ``angle * (1 - softness)``, falls with a smoothstep to 0 at
``angle`` and is 0 beyond. Both the stage reader (the shaped flux fraction) and the
emission sampler (the shaped direction table) use the rules defined once here.
"""
from __future__ import annotations

import functools
import math

import numpy as np

#: Lights that emit from one side only, along their local -Z (UsdLux).
ONE_SIDED_KINDS = ("disk", "rect")
#: Samples of the inverse-CDF table over theta of a shaped profile.
PROFILE_SAMPLES = 4096


def is_one_sided(kind: str) -> bool:
    """Whether a light of ``kind`` emits from one side (a cosine lobe about -Z)."""
    return kind in ONE_SIDED_KINDS


def unshaped_cone_angle(kind: str) -> float:
    """Cone angle (deg) at and above which the cone does not narrow a light's emission."""
    return 90.0 if is_one_sided(kind) else 180.0


def is_shaped(kind: str, cone_angle: float, focus: float) -> bool:
    """True when the shaping changes the emission from the plain (Lambertian or uniform) one."""
    return focus > 0.0 or cone_angle < unshaped_cone_angle(kind)


def shaping_window(theta: np.ndarray, angle_deg: float, softness: float, focus: float
                   ) -> np.ndarray:
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
def profile_table(base_cos_power: int, angle_deg: float, softness: float, focus: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Inverse-CDF table (theta in rad, normalised CDF) of the intensity
    ``cos(theta)**base_cos_power * window``; ValueError when it leaves no emission."""
    limit = np.pi / 2 if base_cos_power > 0 else np.pi
    t_hi = min(np.radians(angle_deg), limit)
    theta = np.linspace(0.0, t_hi, PROFILE_SAMPLES + 1)
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
        profile_table(1 if is_one_sided(kind) else 0, float(cone_angle),
                      float(cone_softness), float(focus))
    except ValueError:
        return False
    return True


def shaping_fraction(kind: str, cone_angle: float, cone_softness: float = 0.0,
                     focus: float = 0.0) -> float:
    """Fraction of an emitter's unshaped flux that UsdLuxShapingAPI lets through.

    The unshaped intensity is ``cos(theta)`` for one-sided disk and rect lights (a hard cone
    of angle a < 90 deg keeps ``sin(a)**2``) and uniform for sphere lights. Cylinder lights
    are not shaped.
    """
    if kind == "cylinder":
        return 1.0
    lambertian = is_one_sided(kind)
    limit = 0.5 * math.pi if lambertian else math.pi
    t_max = math.radians(cone_angle)
    softness = min(max(cone_softness, 0.0), 1.0)
    if focus <= 0.0 and (softness == 0.0 or t_max <= 0.0):
        t = min(t_max, limit)
        return math.sin(t) ** 2 if lambertian else 0.5 * (1.0 - math.cos(t))
    theta = np.linspace(0.0, min(t_max, limit), 20001)
    window = shaping_window(theta, cone_angle, softness, focus)
    base = np.sin(theta) * (np.cos(theta) if lambertian else 1.0)
    total = 0.5 if lambertian else 2.0  # integral of base over the full range
    return float(np.trapezoid(window * base, theta) / total)
