"""The intensity map as a lat-long environment texture: what renderers (a UsdLux DomeLight)
and compositors read, a tiled, mip-mapped EXR (:mod:`.exr_writer`).

OpenEXR's latitude-longitude layout: x is longitude, from +pi at the left edge to -pi at the
right, y latitude, +pi/2 at the top; longitude 0 on the equator looks along +Z, pi/2 along
+X, the poles are +-Y. That frame is a DomeLight's with ``poleAxis`` "scene": its +Y pole is
the stage's up axis, so in a Z-up stage the image's +Y is the stage's +Z and its +Z the
stage's -Y. R, G and B all hold the intensity (cd), so the texture's value in a direction
is the luminaire's intensity toward it.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import OutputError
from ..film.cubemap import bilinear_taps, sample_map
from .exr_writer import ENVMAP_LATLONG, write_tiled_exr
from ..table_cache import kept_table

#: Tile size (pixels) of the texture.
TILE = 64


def dome_to_stage(d: np.ndarray, up_axis: str) -> np.ndarray:
    """Directions (..., 3) in the dome's (OpenEXR lat-long) frame, in stage axes."""
    if up_axis == "Y":
        return d
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([x, -z, y], axis=-1)  # dome +Y is the stage's +Z, dome +Z its -Y


def stage_to_dome(d: np.ndarray, up_axis: str) -> np.ndarray:
    """Directions (..., 3) in stage axes, in the dome's frame."""
    if up_axis == "Y":
        return d
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([x, z, -y], axis=-1)


def latlong_image(intensity_map: np.ndarray, up_axis: str, width: int | None = None
                  ) -> np.ndarray:
    """The cube map (cd) resampled bilinearly at the pixel centres of a 2N x N lat-long
    image: (N, 2N) float32, N twice the cube face size unless ``width`` says otherwise."""
    res = intensity_map.shape[1]
    w = width or 4 * res
    taps = _latlong_taps(res, w, up_axis)
    return sample_map(intensity_map, None, taps).reshape(w // 2, w).astype(np.float32)


@kept_table
def _latlong_taps(res: int, w: int, up_axis: str) -> tuple[np.ndarray, np.ndarray]:
    """The cube-map taps of a 2N x N lat-long image's pixel centres (N = ``w`` / 2), made
    once per layout: a service writes the texture after every few rounds."""
    h = w // 2
    lon = np.pi - 2.0 * np.pi * (np.arange(w) + 0.5) / w
    lat = 0.5 * np.pi - np.pi * (np.arange(h) + 0.5) / h
    lat, lon = np.meshgrid(lat, lon, indexing="ij")
    dome = np.stack([np.cos(lat) * np.sin(lon), np.sin(lat), np.cos(lat) * np.cos(lon)], -1)
    taps = bilinear_taps(dome_to_stage(dome, up_axis).reshape(-1, 3), res)
    for a in taps:
        a.flags.writeable = False
    return taps


def write_latlong_texture(path: str | os.PathLike, intensity_map: np.ndarray,
                          up_axis: str) -> Path:
    """Write the lat-long texture of a cube map (cd) at ``path``: a tiled, mip-mapped EXR
    with R, G and B the intensity, wrapping round in longitude and clamped at the poles."""
    img = latlong_image(intensity_map, up_axis)
    strings = {"ImageDescription": "luminous intensity (cd) by direction, lat-long, dome "
               f"frame with its pole on the stage's +{up_axis}",
               "wrapmodes": "periodic,clamp", "colorInteropID": "lin_rec709_scene",
               "oiio:ColorSpace": "lin_rec709_scene"}
    try:
        return write_tiled_exr(path, {"R": img, "G": img, "B": img}, strings,
                               envmap=ENVMAP_LATLONG, tile=TILE)
    except OSError as exc:
        raise OutputError(f"cannot write the lat-long texture: {exc}", str(path)) from exc
