"""TM-25 ray files: ours read back bit for bit; a file laid out as LED makers publish them
(radiant flux and a shared spectral table) read at the right offsets; a wrong header is
one clear error naming the file."""
import struct

import numpy as np
import pytest

from lumitrace.errors import LumitraceError
from lumitrace import tm25


def _rays(n=1000, seed=1):
    r = np.random.default_rng(seed)
    d = r.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return tm25.RayFile(positions=r.uniform(-2, 2, (n, 3)).astype(np.float32),
                        directions=d.astype(np.float32),
                        flux=np.full(n, 0.25, np.float32),
                        descriptions=("test LED", "lumitrace", "", "", "", "", "350 mA", "",
                                      "made by the test"),
                        date="2026-11-30 08:00:00")


def test_our_file_reads_back_bit_for_bit(tmp_path):
    rays = _rays()
    path = tmp_path / "a.TM25RAY"
    tm25.write_tm25(path, rays)
    back = tm25.read_tm25(path)
    for name in ("positions", "directions", "flux"):
        assert np.array_equal(getattr(back, name), getattr(rays, name))
        assert getattr(back, name).dtype == np.float32
    assert back.photometric and back.luminous_flux == pytest.approx(250.0)
    assert np.isnan(back.radiant_flux)
    assert back.descriptions == rays.descriptions and back.date == rays.date
    assert back.creation_method == tm25.SIMULATION and back.spectral_id == 0
    assert path.stat().st_size == tm25.TEXT_END + 4 + 1000 * 28
    assert tm25.format_tm25(back) == path.read_bytes()


def _vendor_file(path, n=50):
    """Laid out as an LED maker's file: radiant flux and luminous flux per ray, one shared
    spectral table (identifier 3) of 26 points, creation method -1."""
    r = np.random.default_rng(3)
    rec = np.zeros((n, 8), "<f4")
    rec[:, :3] = r.uniform(-1, 1, (n, 3))
    d = r.normal(size=(n, 3))
    rec[:, 3:6] = d / np.linalg.norm(d, axis=1, keepdims=True)
    rec[:, 6] = 1e-4  # W
    rec[:, 7] = 0.03  # lm
    head = bytearray(tm25.TEXT_END)
    struct.pack_into("<4siiffQ28siifffiii", head, 0, b"TM25", 2013, -1, 0.03 * n, 1e-4 * n,
                     n, b"2026-05-12 13:57:44", 0, 3, float("nan"), 380.0, 780.0, 1, 0, 0)
    struct.pack_into("<8i", head, tm25.FLAGS_AT, 1, 1, 1, 0, 1, 0, 0, 0)
    name = "Vendor LED".encode("utf-32-le")
    head[tm25.TEXT_AT:tm25.TEXT_AT + len(name)] = name
    table = struct.pack("<i", 26) + np.column_stack(
        [np.linspace(380, 780, 26), np.linspace(0, 100, 26)]).astype("<f4").tobytes()
    path.write_bytes(bytes(head) + table + struct.pack("<i", 0) + rec.tobytes())
    return rec


def test_a_vendor_layout_reads_at_the_right_offsets(tmp_path):
    path = tmp_path / "v.TM25RAY"
    rec = _vendor_file(path)
    f = tm25.read_tm25(path)
    assert len(f) == 50 and f.photometric and f.spectral_id == 3 and f.creation_method == -1
    assert np.array_equal(f.positions, rec[:, :3]) and np.array_equal(f.directions, rec[:, 3:6])
    assert np.array_equal(f.flux, rec[:, 7])  # the luminous column, not the radiant one
    assert f.descriptions[0] == "Vendor LED" and f.date == "2026-05-12 13:57:44"


@pytest.mark.parametrize("damage,words", [
    (lambda b: b"TM24" + b[4:], "magic"),
    (lambda b: b[:4] + struct.pack("<i", 2020) + b[8:], "version 2020"),
    (lambda b: b[:-5], "the file has"),
    (lambda b: b[:80] + struct.pack("<i", 2) + b[84:], "additional per-ray item"),
    (lambda b: b[:tm25.FLAGS_AT + 8] + struct.pack("<i", 1) + b[tm25.FLAGS_AT + 12:],
     "the file has"),  # a radiant flux column the rays do not have
    (lambda b: b[:tm25.FLAGS_AT + 16] + struct.pack("<i", 0) + b[tm25.FLAGS_AT + 20:],
     "neither radiant nor luminous"),
    (lambda b: b[:1000], "shorter than the header"),
])
def test_a_wrong_header_is_one_clear_error(tmp_path, damage, words):
    good = tmp_path / "good.TM25RAY"
    tm25.write_tm25(good, _rays(20))
    bad = tmp_path / "bad.TM25RAY"
    bad.write_bytes(damage(good.read_bytes()))
    with pytest.raises(LumitraceError) as info:
        tm25.read_tm25(bad)
    assert words in str(info.value) and str(bad) in str(info.value)
