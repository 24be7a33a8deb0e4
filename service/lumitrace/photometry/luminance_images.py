"""Luminance images: what the luminaire looks like from a viewing direction, from its exit
rays (where every escaping photon leaves the luminaire's box, and its direction).

The rays within a cone of half-angle :data:`HALF_ANGLE` about the direction toward the
observer are projected along it onto the plane perpendicular to it; a pixel's luminance is
its rays' flux over the cone's solid angle and the pixel's area (cd/m^2), its standard
error from the rays' fluxes (sqrt(sum w^2), analog photons). The lit area is the luminous
opening seen from the view (:func:`~lumitrace.photometry.luminance.projected_area` of the
opening measured from the same rays, as the luminance table takes it); the mean luminance is
all the cone's flux over the cone's solid angle and that area: the table's intensity over
projected area, measured from other photons. The bright area is the pixels at or above half
the median lit pixel (a boundary pixel counts when it is more than half covered), and its
mean says how much brighter than the opening's mean the part that carries the light is (an
opening lit unevenly). The peak pixel is a maximum of noisy values (biased upward by about
its own error).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import frame
from .luminance import projected_area

#: Standard viewing directions (C, gamma) in degrees: nadir, and the C0 and C90 planes at
#: 45 deg and at the screen-work angles 65 and 85 deg.
VIEWS = ((0.0, 0.0), (0.0, 45.0), (0.0, 65.0), (0.0, 85.0), (90.0, 45.0), (90.0, 65.0),
         (90.0, 85.0))
#: Half-angle (deg) of the cone of directions an image takes its rays from.
HALF_ANGLE = 5.0
#: Pixels across the longer side of an image.
PIXELS = 32


@dataclass(frozen=True)
class LuminanceImage:
    """Luminance (cd/m^2) per pixel seen from (``c``, ``gamma``) deg, rows from the top,
    with standard errors, the pixel's sides (m), the lit area (m^2, the opening seen from the
    view) and the mean luminance over it, the bright area and its mean, and the peak pixel,
    each with its error, and the rays it holds."""

    c: float
    gamma: float
    image: np.ndarray
    sigma: np.ndarray
    pixel_m: tuple[float, float]  # across (right) and up
    lit_area: float
    mean: float
    mean_error: float
    peak: float
    peak_error: float
    rays: int
    bright_area: float = 0.0
    bright_mean: float = 0.0

    def as_dict(self) -> dict:
        """The figures (not the pixels)."""
        return {"c_deg": self.c, "gamma_deg": self.gamma, "pixel_m": list(self.pixel_m),
                "lit_area_m2": self.lit_area, "mean_cd_per_m2": self.mean,
                "mean_error": self.mean_error, "peak_cd_per_m2": self.peak,
                "peak_error": self.peak_error, "rays": self.rays,
                "bright_area_m2": self.bright_area, "bright_mean_cd_per_m2": self.bright_mean}


def photometric_rays(rays, scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A :class:`~lumitrace.tm25.RayFile` of ``scene``'s luminaire (mm, luminaire frame)
    as (positions in m, unit directions, flux in lm) in the photometric frame (C0, C90,
    up) of the luminaire."""
    mpu = scene.meters_per_unit
    m = np.asarray(scene.luminaire_to_world, np.float64) if scene.luminaire_to_world \
        else np.diag([mpu, mpu, mpu, 1.0])
    local = np.asarray(rays.positions, np.float64) / (mpu * 1000.0)
    world = local @ m[:3, :3].T + m[:3, 3]
    d = np.asarray(rays.directions, np.float64) @ m[:3, :3].T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    axes = np.stack(frame.axes(scene.up_axis, frame.luminaire_rotation(scene)))  # rows
    return world @ axes.T, d @ axes.T, np.asarray(rays.flux, np.float64)


def image_axes(view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (right, up) of the image plane seen along ``-view`` (photometric
    frame): right is horizontal (C90 for a view from nadir), up completes the frame."""
    right = np.cross([0.0, 0.0, 1.0], view)
    norm = np.linalg.norm(right)
    right = right / norm if norm > 1e-9 else np.array([0.0, 1.0, 0.0])
    return right, np.cross(view, right)


def luminance_image(positions: np.ndarray, directions: np.ndarray, flux: np.ndarray,
                    c: float, gamma: float, opening=None, half_angle: float = HALF_ANGLE,
                    pixels: int = PIXELS) -> LuminanceImage:
    """The image seen from (``c``, ``gamma``) deg of rays in the photometric frame
    (:func:`photometric_rays`), its lit area that of ``opening`` (a
    :class:`~lumitrace.photometry.distribution.LuminousOpening`; the bright area without
    one)."""
    view = frame.directions(np.array(c), np.array(gamma), "Z")  # the frame's own axes
    cos_half = math.cos(math.radians(half_angle))
    keep = directions @ view >= cos_half
    omega = 2.0 * math.pi * (1.0 - cos_half)
    right, up = image_axes(view)
    p, w = positions[keep], flux[keep]
    if not len(w):
        empty = np.zeros((pixels, pixels))
        return LuminanceImage(c, gamma, empty, empty, (0.0, 0.0), 0.0, 0.0, 0.0, 0.0, 0.0, 0)
    x, y = p @ right, p @ up
    lo = np.array([np.percentile(x, 0.05), np.percentile(y, 0.05)])
    hi = np.array([np.percentile(x, 99.95), np.percentile(y, 99.95)])
    # as many pixels along each axis: a view at grazing angles is as well resolved across
    # its narrow side (the pixels are then not square: ``pixel_m`` gives both sides)
    centre, side = 0.5 * (lo + hi), 1.1 * np.maximum(hi - lo, 1e-6)
    px, py = side / pixels
    i = np.clip(((centre[1] + 0.5 * side[1] - y) / py).astype(np.int64), 0, pixels - 1)
    j = np.clip(((x - centre[0] + 0.5 * side[0]) / px).astype(np.int64), 0, pixels - 1)
    cell = i * pixels + j
    scale = 1.0 / (omega * px * py)
    img = np.bincount(cell, w, pixels * pixels).reshape(pixels, pixels) * scale
    sig = np.sqrt(np.bincount(cell, w * w, pixels * pixels)).reshape(pixels, pixels) * scale
    smooth = _box3(img)  # the mask from a 3 x 3 mean: a noisy pixel does not flip it
    bright = float((smooth >= 0.5 * float(np.median(smooth[smooth > 0]))).sum()) * px * py
    area = float(projected_area(opening, c, gamma)) if opening is not None else bright
    k = np.unravel_index(int(np.argmax(img)), img.shape)
    total, total_var = float(w.sum()), float((w * w).sum())
    return LuminanceImage(c, gamma, img, sig, (float(px), float(py)), area,
                          total / (omega * area),
                          math.sqrt(total_var) / (omega * area), float(img[k]),
                          float(sig[k]), int(len(w)), bright, total / (omega * bright))


def _box3(a: np.ndarray) -> np.ndarray:
    """Mean over each pixel's 3 x 3 neighbourhood (zero outside)."""
    p = np.pad(a, 1)
    return sum(p[i:i + a.shape[0], j:j + a.shape[1]] for i in range(3) for j in range(3)) / 9.0


def luminance_images(positions, directions, flux, views=VIEWS, **kw) -> list[LuminanceImage]:
    """An image for each of ``views`` ((C, gamma) deg)."""
    return [luminance_image(positions, directions, flux, c, g, **kw) for c, g in views]
