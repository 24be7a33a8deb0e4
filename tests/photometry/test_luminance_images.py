"""Luminance images from the exit rays: the Lambertian disc's lit-area mean against its
closed form and against the luminance table at every standard view, the demo's and the
louvre's against the table over the image's own cone; the files read back."""
from __future__ import annotations

import functools
import json
import math

import numpy as np
import OpenEXR
import OpenImageIO as oiio
import pytest

from lumitrace.photometry import frame
from lumitrace.photometry.luminance import luminance_table, projected_area, sample
from lumitrace.photometry.luminance_images import (HALF_ANGLE, VIEWS, image_axes,
                                                   photometric_rays)
from lumitrace.publish.luminance_images import images_from_rays
from lumitrace.trace.exit_rays import exit_rays
from helpers.traced import traced


@functools.lru_cache(maxsize=1)
def _disc_rays():
    scene, _, ph, _ = traced("disc")
    return scene, ph, exit_rays(scene, 2_000_000, seed=3)


def test_disc_images_mean_equals_the_closed_form_and_the_table(tmp_path):
    scene, ph, rays = _disc_rays()
    images = images_from_rays(rays, scene, tmp_path, "disc")
    assert [(i.c, i.gamma) for i in images] == list(VIEWS)
    want = 1000.0 / (math.pi * math.pi * 0.05 ** 2)  # flux / (pi A), the stage's disc
    for image in images:
        table = luminance_table(ph.grid, ph.opening, c=[image.c], gamma=[image.gamma])
        lum, sig = float(table.luminance[0, 0]), float(table.sigma[0, 0])
        # the lit area is the disc seen from the view: A cos(gamma), to the pixels' edge
        area = math.pi * 0.05 ** 2 * math.cos(math.radians(image.gamma))
        assert image.lit_area == pytest.approx(area, rel=0.04), image.gamma
        assert image.mean == pytest.approx(want, abs=3.0 * image.mean_error + 0.02 * want)
        assert image.mean == pytest.approx(
            lum, abs=3.0 * math.hypot(image.mean_error, sig) + 0.03 * lum)
        # the pixels hold all of the cone's flux: their sum is the intensity over the cone
        px, py = image.pixel_m
        omega = 2.0 * math.pi * (1.0 - math.cos(math.radians(5.0)))
        assert image.image.sum() * px * py * omega == pytest.approx(
            rays.flux.astype(float)[:1].item() * image.rays, rel=1e-4)


def _cone_luminance(grid, opening, c, gamma, n=20_000):
    """The luminance table's value averaged over the image's cone (the directions it takes
    its rays from, uniform in solid angle): intensity over the opening seen from the view."""
    rng = np.random.default_rng(0)
    view = frame.directions(np.array(c), np.array(gamma), "Z")
    right, up = image_axes(view)
    cos_t = 1.0 - rng.random(n) * (1.0 - math.cos(math.radians(HALF_ANGLE)))
    phi = rng.random(n) * 2.0 * math.pi
    sin_t = np.sqrt(1.0 - cos_t ** 2)
    d = cos_t[:, None] * view + sin_t[:, None] * (np.cos(phi)[:, None] * right
                                                  + np.sin(phi)[:, None] * up)
    g = np.degrees(np.arccos(np.clip(-d[:, 2], -1.0, 1.0)))
    cc = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 360.0
    area = float(projected_area(opening, c, gamma))
    return (float(sample(grid, cc, g).mean()) / area,
            float(sample(grid, cc, g, sigma=True).mean()) / area)  # correlated: an upper bound


@pytest.mark.parametrize("name", ["demo", "louvre"])
def test_an_unevenly_lit_opening_mean_equals_the_table(name, tmp_path):
    """On luminaires whose opening is not evenly lit, the image's mean over the opening seen
    from the view is the table's luminance over the same directions; the bright part's
    mean is above it."""
    scene, _, ph, _ = traced(name)
    rays = exit_rays(scene, 1_000_000, seed=5)
    images = images_from_rays(rays, scene, tmp_path, name)
    for image in images:
        assert image.lit_area == pytest.approx(
            float(projected_area(ph.opening, image.c, image.gamma)), rel=0.03)
        lum, sig = _cone_luminance(ph.grid, ph.opening, image.c, image.gamma)
        assert image.mean == pytest.approx(
            lum, abs=3.0 * math.hypot(image.mean_error, sig) + 0.02 * lum), image.as_dict()
    nadir = images[0]
    assert nadir.bright_mean > 1.03 * nadir.mean and nadir.bright_area < nadir.lit_area


def test_image_files_read_back(tmp_path):
    scene, _, rays = _disc_rays()
    images = images_from_rays(rays, scene, tmp_path, "disc")
    doc = json.loads((tmp_path / "disc.luminance.json").read_text())
    assert len(doc["views"]) == len(VIEWS) and doc["units"] == "cd/m2"
    for image, view in zip(images, doc["views"]):
        exr = OpenEXR.File(str(tmp_path / view["exr"]))
        y = exr.channels()["Y"].pixels
        np.testing.assert_allclose(y, image.image, rtol=1e-6)
        assert json.loads(exr.header()["lumitrace"])["mean_cd_per_m2"] == view["mean_cd_per_m2"]
        png = oiio.ImageBuf(str(tmp_path / view["exr"].replace(".exr", ".png")))
        spec = png.spec()
        px, py = image.pixel_m
        # square pixels: the PNG's aspect is the image's own
        assert spec.width / spec.height == pytest.approx(px / py, rel=0.05)
