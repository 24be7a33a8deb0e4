"""Writing luminance images (:mod:`lumitrace.photometry.luminance_images`): per view an
OpenEXR file (channels ``Y``, luminance cd/m^2, and ``sigma``, its standard error; the
pixel's sides in ``pixelAspectRatio`` and the figures as JSON in the ``lumitrace``
attribute) and a PNG scaled to the image's peak (square pixels, nearest neighbour), and
``NAME.luminance.json`` with every view's figures."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import OpenEXR
import OpenImageIO as oiio

from ..atomic import atomic_path, write_text
from ..errors import OutputError


def image_names(name: str, image) -> str:
    """``NAME.luminance.C<c>G<gamma>`` of a view (degrees rounded)."""
    return f"{name}.luminance.C{image.c:g}G{image.gamma:g}"


def _exr(path: Path, image) -> None:
    px, py = image.pixel_m
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "pixelAspectRatio": float(px / py) if py > 0 else 1.0,
              "lumitrace": json.dumps({**image.as_dict(), "units": "cd/m2"})}
    channels = {"Y": np.ascontiguousarray(image.image, np.float32),
                "sigma": np.ascontiguousarray(image.sigma, np.float32)}
    with atomic_path(path) as tmp:
        OpenEXR.File(header, channels).write(str(tmp))


def _png(path: Path, image) -> None:
    px, py = image.pixel_m
    a = image.image / image.peak if image.peak > 0 else image.image
    if px > 0 and py > 0:  # square pixels, nearest neighbour, at most 1024 across
        rows, cols = a.shape
        t = max(min(px, py) / 4.0, max(cols * px, rows * py) / 1024.0)
        i = np.minimum((np.arange(int(round(rows * py / t))) * t / py).astype(int), rows - 1)
        j = np.minimum((np.arange(int(round(cols * px / t))) * t / px).astype(int), cols - 1)
        a = a[i][:, j]
    rgb = np.ascontiguousarray(np.repeat((255.0 * np.sqrt(np.clip(a, 0.0, 1.0)))
                                         .astype(np.uint8)[:, :, None], 3, axis=2))
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), oiio.ImageSpec(rgb.shape[1], rgb.shape[0],
                                                                3, "uint8")):
            raise OutputError(f"cannot write the PNG: {oiio.geterror()}", where=str(path))
        out.write_image(rgb)
        out.close()


def write_luminance_images(images, out_dir: str | Path, name: str) -> dict[str, Path]:
    """Write every image's EXR and PNG and the figures' JSON into ``out_dir``; returns the
    paths by file name."""
    out = Path(out_dir)
    written = {}
    for image in images:
        stem = image_names(name, image)
        for suffix, writer in ((".exr", _exr), (".png", _png)):
            path = out / f"{stem}{suffix}"
            writer(path, image)
            written[path.name] = path
    figures = out / f"{name}.luminance.json"
    write_text(figures, json.dumps({"units": "cd/m2", "views": [
        {**i.as_dict(), "exr": f"{image_names(name, i)}.exr"} for i in images]}, indent=1)
        + "\n")
    written[figures.name] = figures
    return written


def images_from_rays(rays, scene, out_dir: str | Path, name: str) -> list:
    """The standard views' images of a luminaire's exit rays (a
    :class:`~lumitrace.tm25.RayFile` of ``scene``), written into ``out_dir``."""
    from ..film.goniometer import Goniometer
    from ..photometry.distribution import opening_of_exits
    from ..photometry.luminance_images import luminance_images, photometric_rays

    positions, directions, flux = photometric_rays(rays, scene)
    box = Goniometer.of(scene)
    opening = opening_of_exits(positions, flux, box.lo, box.hi)
    images = luminance_images(positions, directions, flux, opening=opening)
    write_luminance_images(images, out_dir, name)
    return images
