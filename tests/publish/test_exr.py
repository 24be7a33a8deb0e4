"""The intensity map EXR: round trips, OpenImageIO compatibility, atomic failure."""
from __future__ import annotations

import errno
import json
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from lumitrace.film import cubemap as cm
from lumitrace.publish import exr, exr_writer
from lumitrace.errors import LumitraceError, OutputError

RES = 8


def make_channels(res: int = RES, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    shape = cm.image_shape(res)
    return {
        "Y": rng.uniform(0, 500, size=shape),  # float64: stored as float32
        "raw.Y": rng.exponential(300, size=shape),
        "count": rng.integers(0, 2**24, size=shape),
    }


METADATA = {
    "software": "lumitrace test",
    "photons": 123456789012345,
    "relativeError": 0.1 + 0.2,
    "threshold": 1.0 / 3.0,
    "tiny": 5e-324,
    "huge": 1.7976931348623157e308,
    "negative": -2.5e-17,
    "converged": False,
    "seed": 0,
    "nothing": None,
    "stage": "Leuchte \u00e9\u00e8 \u6f22",
    "units": {"Y": "cd", "raw.Y": "cd", "count": "photons"},
    "emitters": [{"path": "/Luminaire/LED", "flux": 1000.0000000000001, "photons": 7}],
}


def files_in(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_round_trip_channels_and_metadata(tmp_path):
    path = tmp_path / "lamp.intensity.exr"
    channels = make_channels()
    exr.write_intensity_exr(path, channels, METADATA)
    assert files_in(tmp_path) == ["lamp.intensity.exr"]
    got, meta, header = exr.read_intensity_exr(path)
    assert set(got) == {"Y", "raw.Y", "count"}
    for name, data in channels.items():
        assert got[name].dtype == np.float32
        assert got[name].shape == (6 * RES, RES)
        assert_array_equal(got[name], np.asarray(data, dtype=np.float32))
    assert_array_equal(got["count"].astype(np.int64), channels["count"])  # exact < 2**24
    assert meta == METADATA
    for key in ("relativeError", "threshold", "tiny", "huge", "negative"):
        assert meta[key] == METADATA[key] and type(meta[key]) is float
    assert header["envmap"] == OpenEXR.ENVMAP_CUBE
    assert header["compression"] == OpenEXR.ZIP_COMPRESSION
    assert json.loads(header[exr.METADATA_ATTRIBUTE]) == METADATA
    assert header["lumitrace:photons"] == "123456789012345"
    assert header["lumitrace:software"] == "lumitrace test"


def test_numpy_metadata_values_are_converted(tmp_path):
    path = tmp_path / "np.intensity.exr"
    meta = {"photons": np.int64(2**62), "error": np.float64(0.1), "flag": np.bool_(True),
            "direction": np.array([0.0, -1.0, 1e-300]), "res": np.int32(RES),
            "file": Path("a/b.ies")}
    exr.write_intensity_exr(path, make_channels(), meta)
    _, got, _ = exr.read_intensity_exr(path)
    assert got == {"photons": 2**62, "error": 0.1, "flag": True,
                   "direction": [0.0, -1.0, 1e-300], "res": RES, "file": "a/b.ies"}


def test_other_resolutions_and_single_channel(tmp_path):
    for res in (1, 2, 33):
        path = tmp_path / f"r{res}.intensity.exr"
        y = np.linspace(0, 1, 6 * res * res, dtype=np.float32).reshape(6 * res, res)
        exr.write_intensity_exr(path, {"Y": y}, {"resolution": res})
        got, meta, _ = exr.read_intensity_exr(path)
        assert_array_equal(got["Y"], y)
        assert meta == {"resolution": res}


def test_file_reads_with_openimageio(tmp_path):
    oiio = pytest.importorskip("OpenImageIO")
    path = tmp_path / "lamp.intensity.exr"
    channels = make_channels()
    exr.write_intensity_exr(path, channels, METADATA)
    inp = oiio.ImageInput.open(str(path))
    assert inp, oiio.geterror()
    try:
        spec = inp.spec()
        assert (spec.width, spec.height, spec.nchannels) == (RES, 6 * RES, 3)
        assert set(spec.channelnames) == {"Y", "raw.Y", "count"}
        assert all(str(f) == "float" for f in spec.channelformats) or str(spec.format) == "float"
        # OIIO reports envmap = CUBE as a cube face environment, with edge-centred samples.
        assert spec.get_string_attribute("textureformat") == "CubeFace Environment"
        assert spec.get_int_attribute("oiio:sampleborder") == 1
        assert json.loads(spec.get_string_attribute(exr.METADATA_ATTRIBUTE)) == METADATA
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
    finally:
        inp.close()
    for i, name in enumerate(spec.channelnames):
        assert_array_equal(pixels[..., i], np.asarray(channels[name], dtype=np.float32))


@pytest.mark.parametrize("bad, message", [
    ({"Y": np.nan}, "'Y'"),
    ({"raw.Y": np.inf}, "'raw.Y'"),
    ({"raw.Y": -np.inf}, "'raw.Y'"),
    ({"Y": 1e39}, "'Y'"),  # finite in float64, Inf in float32
    ({"count": -1.0}, "'count'"),
])
def test_bad_values_leave_the_existing_file_untouched(tmp_path, bad, message):
    path = tmp_path / "lamp.intensity.exr"
    exr.write_intensity_exr(path, make_channels(), METADATA)
    before = path.read_bytes()
    channels = make_channels(seed=1)
    for name, value in bad.items():
        channels[name] = channels[name].astype(np.float64)
        channels[name][5, 3] = value
    with pytest.raises(OutputError, match=message) as info:
        exr.write_intensity_exr(path, channels, METADATA)
    assert str(path) in str(info.value)
    assert "row 5, column 3" in str(info.value)
    assert path.read_bytes() == before
    assert files_in(tmp_path) == ["lamp.intensity.exr"]


def test_bad_shapes_and_metadata_are_refused(tmp_path):
    path = tmp_path / "lamp.intensity.exr"
    exr.write_intensity_exr(path, make_channels(), METADATA)
    before = path.read_bytes()
    good = make_channels()
    cases = [
        ({"Y": np.zeros((6 * RES, RES + 1))}, METADATA, "'Y'.*cube map"),
        ({"Y": np.zeros((5, 1))}, METADATA, "'Y'.*cube map"),
        ({"Y": np.zeros(6 * RES)}, METADATA, "'Y'.*2D"),
        ({"Y": good["Y"], "count": np.zeros((12, 2))}, METADATA, "'count'.*shape"),
        ({"Y": good["Y"].astype(complex)}, METADATA, "'Y'.*dtype"),
        ({}, METADATA, "no channels"),
        (good, {"relativeError": float("nan")}, "relativeError"),
        (good, {"emitters": [{"flux": float("inf")}]}, r"emitters\[0\].flux"),
        (good, {"bad": object()}, "bad"),
        (good, ["not", "a", "mapping"], "mapping"),
    ]
    for channels, meta, message in cases:
        with pytest.raises(OutputError, match=message):
            exr.write_intensity_exr(path, channels, meta)
        assert path.read_bytes() == before
    assert files_in(tmp_path) == ["lamp.intensity.exr"]


def test_failure_inside_the_writer_leaves_the_existing_file_untouched(tmp_path, monkeypatch):
    path = tmp_path / "lamp.intensity.exr"
    exr.write_intensity_exr(path, make_channels(), METADATA)
    before = path.read_bytes()

    class HalfWritten:  # the file system fills up half way through the file
        def __init__(self, name, mode):
            self.f = open(name, mode)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

        def write(self, data):
            self.f.write(data[:len(data) // 2])
            raise OSError(errno.ENOSPC, "disk full")

    monkeypatch.setattr(exr_writer, "open", HalfWritten, raising=False)
    with pytest.raises(OutputError, match="disk full"):
        exr.write_intensity_exr(path, make_channels(seed=2), METADATA)
    assert path.read_bytes() == before
    assert files_in(tmp_path) == ["lamp.intensity.exr"]


def test_read_errors_name_the_file(tmp_path):
    with pytest.raises(LumitraceError, match="not found"):
        exr.read_intensity_exr(tmp_path / "missing.exr")
    junk = tmp_path / "junk.exr"
    junk.write_bytes(b"not an exr at all")
    with pytest.raises(LumitraceError, match="junk.exr"):
        exr.read_intensity_exr(junk)
    flat = tmp_path / "flat.exr"
    OpenEXR.File({"type": OpenEXR.scanlineimage},
                 {"Y": np.zeros((6, 1), np.float32)}).write(str(flat))
    with pytest.raises(LumitraceError, match="not a cube map"):
        exr.read_intensity_exr(flat)
    bad_json = tmp_path / "bad.exr"
    OpenEXR.File({"type": OpenEXR.scanlineimage, "envmap": OpenEXR.ENVMAP_CUBE,
                  "lumitrace": "{oops"}, {"Y": np.zeros((6, 1), np.float32)}).write(str(bad_json))
    with pytest.raises(LumitraceError, match="not valid JSON"):
        exr.read_intensity_exr(bad_json)


def test_latlong_copy(tmp_path):
    res = 6
    td = cm.texel_directions(res)
    zenith = 100.0 * (1.0 + td[..., 2])  # a smooth map
    path = tmp_path / "lamp.latlong.exr"
    exr.write_latlong_exr(path, {"Y": zenith, "flat": np.full(cm.image_shape(res), 7.0)},
                          {"source": "lamp.intensity.exr"})
    f = OpenEXR.File(str(path), separate_channels=True)
    header = f.header()
    assert header["envmap"] == OpenEXR.ENVMAP_LATLONG
    assert json.loads(header["lumitrace"]) == {"source": "lamp.intensity.exr"}
    y = f.channels()["Y"].pixels
    assert y.shape == (2 * res, 4 * res)
    assert_allclose(f.channels()["flat"].pixels, 7.0, rtol=1e-7)
    dirs = cm.latlong_directions(2 * res)
    # Bilinear on the cube: close to the smooth function, exact by symmetry at +Y.
    assert_allclose(y, 100.0 * (1.0 + dirs[..., 2]), atol=5.0)  # h**2 / 4 * f'', h = 0.4
    assert_allclose(y[0], 100.0, rtol=1e-6)  # first row is +Y
    single = tmp_path / "single.exr"
    exr.write_latlong_exr(single, zenith, height=5)
    assert OpenEXR.File(str(single)).channels()["Y"].pixels.shape == (5, 10)
    with pytest.raises(OutputError):
        exr.write_latlong_exr(single, np.zeros((7, 2)))


@pytest.mark.parametrize("name", ["a\0b", "x" * 256, "\ud800"])
def test_a_channel_name_the_format_cannot_hold_is_refused_and_nothing_is_lost(tmp_path, name):
    path = tmp_path / "lamp.intensity.exr"
    exr.write_intensity_exr(path, make_channels(), METADATA)
    before = path.read_bytes()
    channels = make_channels(seed=2)
    channels[name] = channels.pop("Y")
    with pytest.raises(OutputError, match="OpenEXR name") as err:
        exr.write_intensity_exr(path, channels, METADATA)
    assert err.value.where == str(path)
    assert path.read_bytes() == before
    assert files_in(tmp_path) == ["lamp.intensity.exr"]


def test_a_metadata_key_too_long_for_a_name_stays_in_the_json_alone(tmp_path):
    path = tmp_path / "lamp.intensity.exr"
    key = "k" * 250  # "lumitrace:" + key: 260 bytes, over OpenEXR's 255
    exr.write_intensity_exr(path, make_channels(), {**METADATA, key: 1.5, "short": 2})
    _, meta, header = exr.read_intensity_exr(path)
    assert meta[key] == 1.5 and meta["short"] == 2
    assert header["lumitrace:short"] == "2"
    assert not any(k.endswith(key) for k in header)
