"""The scanline and the tiled, mip-mapped EXR writers, read back by OpenImageIO and OpenEXR
(independent readers of the format): every level's pixels exactly, tiles, attributes."""
from __future__ import annotations

import numpy as np
import OpenEXR
import OpenImageIO as oiio
import pytest

from lumitrace.publish.exr_writer import (ENVMAP_CUBE, ENVMAP_LATLONG, mip_levels,
                                         write_scanline_exr, write_tiled_exr)


def _levels(path):
    """Every level of the file as OpenImageIO reads it: (h, w, channels) float32 arrays."""
    inp = oiio.ImageInput.open(str(path))
    out, level = [], 0
    while inp.seek_subimage(0, level):
        out.append(inp.read_image("float"))
        level += 1
    return inp, out


@pytest.mark.parametrize("shape", [(128, 256), (3, 5), (70, 130), (1, 1)])
def test_every_level_reads_back_exactly(tmp_path, shape):
    rng = np.random.default_rng(7)
    smooth = np.add.outer(np.arange(shape[0]), 2.0 * np.arange(shape[1])).astype(np.float32)
    noise = rng.random(shape).astype(np.float32)  # incompressible: tiles stored raw
    path = tmp_path / "t.exr"
    write_tiled_exr(path, {"R": noise, "G": smooth, "B": np.zeros(shape)})
    inp, levels = _levels(path)
    # MIPMAP_LEVELS rounded down: floor(log2(longest side)) + 1 levels, down to 1 x 1
    assert len(levels) == int(np.floor(np.log2(max(shape)))) + 1
    assert inp.spec().tile_width == inp.spec().tile_height == 64
    assert inp.spec().get_string_attribute("compression") == "zip"
    for got, r, g in zip(levels, mip_levels(noise), mip_levels(smooth)):
        assert np.array_equal(got[..., 0], r) and np.array_equal(got[..., 1], g)
        assert not got[..., 2].any()
    for k, got in enumerate(levels):
        assert got.shape[:2] == (max(1, shape[0] >> k), max(1, shape[1] >> k))
    # OpenEXR's own reader: the first level, bit for bit
    f = OpenEXR.File(str(path), separate_channels=True)
    assert np.array_equal(f.channels()["R"].pixels, noise)


def test_a_level_is_the_mean_of_four_pixels():
    img = np.arange(32.0).reshape(4, 8)
    one = mip_levels(img)[1]
    assert np.array_equal(one, img.reshape(2, 2, 4, 2).mean(axis=(1, 3)).astype(np.float32))
    assert [lv.shape for lv in mip_levels(img)] == [(4, 8), (2, 4), (1, 2), (1, 1)]
    assert mip_levels(img)[-1][0, 0] == np.float32(img.mean())


def test_a_latlong_environment_matches_openimageio_texture_maker(tmp_path):
    """Inside its edges the first level is what OpenImageIO's texture maker writes (it sets
    the border rows and columns to their means, as if they were sampled on the poles and
    the seam); OpenImageIO reads it as a lat-long environment with the given attributes."""
    rng = np.random.default_rng(3)
    img = (100.0 * rng.random((64, 128))).astype(np.float32)
    ours = tmp_path / "ours.exr"
    write_tiled_exr(ours, {c: img for c in "RGB"}, {"wrapmodes": "periodic,clamp",
                                                    "ImageDescription": "test"},
                    envmap=ENVMAP_LATLONG)
    theirs = tmp_path / "theirs.exr"
    spec = oiio.ImageSpec()
    spec.tile_width = spec.tile_height = 64
    spec.attribute("compression", "zip")
    assert oiio.ImageBufAlgo.make_texture(oiio.MakeTxEnvLatl,
                                          oiio.ImageBuf(np.repeat(img[..., None], 3, 2)),
                                          str(theirs), spec)
    inp, mine = _levels(ours)
    _, made = _levels(theirs)
    assert len(mine) == len(made)
    assert np.array_equal(mine[0][1:-1, 1:-1], made[0][1:-1, 1:-1])
    s = inp.spec()
    assert s.get_string_attribute("textureformat") == "LatLong Environment"
    assert s.get_string_attribute("wrapmodes") == "periodic,clamp"
    assert s.get_string_attribute("ImageDescription") == "test"


@pytest.mark.parametrize("shape", [(384, 64), (17, 3), (16, 5), (1, 1)])
def test_a_scanline_image_reads_back_exactly(tmp_path, shape):
    """Blocks of 16 lines, the last one short; noise stored raw, smooth rows deflated."""
    rng = np.random.default_rng(11)
    noise = rng.random(shape).astype(np.float32)
    smooth = np.add.outer(np.arange(shape[0]), 0.5 * np.arange(shape[1]))
    counts = rng.integers(0, 2**24, shape)
    path = tmp_path / "s.exr"
    long = "lumitrace:" + "a_name_longer_than_thirty_one_bytes"
    write_scanline_exr(path, {"raw.Y": noise, "Y": smooth, "count": counts},
                       {"comments": "three channels", long: "kept"}, envmap=ENVMAP_CUBE)
    f = OpenEXR.File(str(path), separate_channels=True)
    got = f.channels()
    assert sorted(got) == ["Y", "count", "raw.Y"]
    assert np.array_equal(got["raw.Y"].pixels, noise)
    assert np.array_equal(got["Y"].pixels, smooth.astype(np.float32))
    assert np.array_equal(got["count"].pixels, counts.astype(np.float32))
    h = f.header()
    assert h["envmap"] == OpenEXR.ENVMAP_CUBE and h["compression"] == OpenEXR.ZIP_COMPRESSION
    assert h["comments"] == "three channels" and h[long] == "kept"
    inp = oiio.ImageInput.open(str(path))
    s = inp.spec()
    assert (s.height, s.width, s.tile_width) == (*shape, 0)
    assert s.channelnames == ("Y", "count", "raw.Y")
    assert np.array_equal(inp.read_image("float")[..., 2], noise)


def test_a_scanline_image_with_short_names_sets_no_long_name_flag(tmp_path):
    """The version's long-name flag only where a name needs it (readers before OpenEXR 1.7
    refuse a file with it)."""
    path = tmp_path / "s.exr"
    write_scanline_exr(path, {"Y": np.ones((6, 1))}, {"x" * 31: "31 bytes"})
    assert int.from_bytes(path.read_bytes()[4:8], "little") == 2
    write_scanline_exr(path, {"Y": np.ones((6, 1))}, {"x" * 32: "32 bytes"})
    assert int.from_bytes(path.read_bytes()[4:8], "little") == 2 | 0x400
    assert OpenEXR.File(str(path)).header()["x" * 32] == "32 bytes"
