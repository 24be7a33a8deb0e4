"""IES TM-25 ray files: a light source as rays (start point in mm, unit direction, flux),
the near-field counterpart of an IES or EULUMDAT file, as LED makers publish them.

The TM-25-13 layout, little-endian throughout (TM-25-20 reads 2013 files): a 256-byte
header (magic ``TM25``, version 2013, creation method, total luminous and radiant flux, the
ray count as u64, date, start-position flag, spectral identifier and wavelengths, table and
item counts), eight known-data flags, nine UTF-32 description strings of 1000 code points,
the spectral tables (identifier 3: one, 4: one per spectrum; each a count and pairs of
wavelength and value), the count of additional item names and the additional text block,
then the rays: x y z kx ky kz and the columns the flags enable, all f32.

Read: position, direction, radiant flux, per-ray wavelength and luminous flux columns;
Stokes, tristimulus and spectrum-index columns are skipped over, as are the spectral
tables (lumitrace traces luminous flux). Refused, with one error naming the file: another
magic or version, files whose size does not match their header, flag combinations the
standard forbids, and additional per-ray items.
"""
from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field

import numpy as np

from .atomic import atomic_path
from .errors import LumitraceError

MAGIC = b"TM25"
VERSION = 2013
#: Creation method of a simulated ray set.
SIMULATION = 0
FLAGS_AT = 256
TEXT_AT = 288
TEXT_FIELDS = 9
TEXT_CHARS = 1000
TEXT_END = TEXT_AT + TEXT_FIELDS * TEXT_CHARS * 4
#: The known-data flags, in file order, and the f32 columns each adds to a ray record.
FLAGS = ("position", "direction", "radiant_flux", "wavelength", "luminous_flux", "stokes",
         "tristimulus", "spectrum_index")
COLUMNS = {"position": 3, "direction": 3, "radiant_flux": 1, "wavelength": 1,
           "luminous_flux": 1, "stokes": 6, "tristimulus": 2, "spectrum_index": 1}
_HEAD = struct.Struct("<4siiffQ28siifffiii")


@dataclass
class RayFile:
    """The rays of a TM-25 file: ``positions`` (N, 3) mm and ``directions`` (N, 3) as f32,
    ``flux`` (N,) per ray (lm where the file has luminous flux, else W), the header's
    totals (NaN where unknown) and its text fields."""

    positions: np.ndarray
    directions: np.ndarray
    flux: np.ndarray
    photometric: bool = True
    luminous_flux: float = float("nan")
    radiant_flux: float = float("nan")
    wavelengths: np.ndarray | None = None
    radiant: np.ndarray | None = None  # radiant flux (W) per ray, where the file has it
    descriptions: tuple[str, ...] = ("",) * TEXT_FIELDS
    creation_method: int = SIMULATION
    date: str = ""
    spectral_id: int = 0
    extra: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.flux)


def _error(message: str, path) -> LumitraceError:
    return LumitraceError(f"not a usable TM-25 ray file: {message}", str(path))


def _text(raw: bytes) -> str:
    s = raw.decode("utf-32-le", errors="replace")
    return s.split("\0", 1)[0]


def summary(source: "str | os.PathLike | RayFile") -> tuple[float | None, np.ndarray]:
    """What a light emitting a ray file (a path, or the file read) needs to know of it: the
    luminous flux (lm) it states (its header's, else the sum of its rays'; None for a
    radiometric-only file) and the half extents (3,) of its start points about the origin
    (mm)."""
    f = source if isinstance(source, RayFile) else read_tm25(source)
    extent = np.abs(f.positions).max(axis=0).astype(np.float64) if len(f) else np.zeros(3)
    if not f.photometric:
        return None, extent
    if np.isfinite(f.luminous_flux) and f.luminous_flux > 0:
        return float(f.luminous_flux), extent
    return float(f.flux.astype(np.float64).sum()), extent


def header_texts(path: str | os.PathLike) -> tuple[str, ...] | None:
    """The nine description fields of a TM-25 file's header (read alone, not the rays);
    None for a file that is not a TM-25 ray file."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(TEXT_END)
    except OSError:
        return None
    if len(head) < TEXT_END or head[:4] != MAGIC:
        return None
    return tuple(_text(head[TEXT_AT + 4 * TEXT_CHARS * k:TEXT_AT + 4 * TEXT_CHARS * (k + 1)])
                 for k in range(TEXT_FIELDS))


def read_tm25(path: str | os.PathLike) -> RayFile:
    """Read a TM-25 ray file (see the module docstring for what is supported)."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise LumitraceError(f"cannot read the ray file: {exc.strerror}", path) from None
    if len(data) < TEXT_END + 4:
        raise _error(f"{len(data)} bytes is shorter than the header ({TEXT_END + 4})", path)
    (magic, version, method, phi_v, phi_e, count, date, _start, spectral, _wl, wl_lo, wl_hi,
     n_spectra, n_items, text_size) = _HEAD.unpack_from(data, 0)
    if magic != MAGIC:
        raise _error(f"magic {magic!r}, not {MAGIC!r}", path)
    if version != VERSION:
        raise _error(f"format version {version} (only {VERSION} is known)", path)
    flags = dict(zip(FLAGS, struct.unpack_from("<8i", data, FLAGS_AT)))
    if any(v not in (0, 1) for v in flags.values()):
        raise _error(f"known-data flags must be 0 or 1, got {list(flags.values())}", path)
    if not (flags["position"] and flags["direction"]):
        raise _error("rays without start points or directions", path)
    if not (flags["radiant_flux"] or flags["luminous_flux"]):
        raise _error("neither radiant nor luminous flux per ray", path)
    if spectral not in range(5):
        raise _error(f"spectral data identifier {spectral} is not 0 to 4", path)
    if spectral in (2, 4) and not flags["radiant_flux"]:
        raise _error(f"spectral identifier {spectral} needs the radiant flux column", path)
    if (spectral == 2) != bool(flags["wavelength"]):
        raise _error("per-ray wavelengths and spectral identifier 2 go together", path)
    if (spectral == 4) != bool(flags["spectrum_index"]):
        raise _error("per-ray spectrum indices and spectral identifier 4 go together", path)
    if flags["tristimulus"] and not (flags["luminous_flux"] and spectral == 0):
        raise _error("tristimulus values need luminous flux and no spectral data", path)
    if flags["stokes"] and not flags["radiant_flux"]:
        raise _error("Stokes parameters need the radiant flux column", path)
    if n_items:
        raise _error(f"{n_items} additional per-ray item(s) are not supported", path)
    texts = tuple(_text(data[TEXT_AT + 4 * TEXT_CHARS * k:TEXT_AT + 4 * TEXT_CHARS * (k + 1)])
                  for k in range(TEXT_FIELDS))
    at = TEXT_END
    for _ in range({3: 1, 4: max(n_spectra, 0)}.get(spectral, 0)):  # spectral tables
        if at + 4 > len(data):
            raise _error("truncated in its spectral tables", path)
        (points,) = struct.unpack_from("<i", data, at)
        if points < 0:
            raise _error(f"a spectral table of {points} points", path)
        at += 4 + 8 * points
    if at + 4 > len(data):
        raise _error("truncated before its rays", path)
    (names,) = struct.unpack_from("<i", data, at)
    if names:
        raise _error(f"{names} additional item name(s) are not supported", path)
    at += 4 + max(text_size, 0)
    width = sum(COLUMNS[f] for f in FLAGS if flags[f])
    if at + count * 4 * width != len(data):
        raise _error(f"{count} rays of {4 * width} bytes from byte {at} need "
                     f"{at + count * 4 * width} bytes, the file has {len(data)}", path)
    rec = np.frombuffer(data, dtype="<f4", count=count * width, offset=at).reshape(count, width)
    cols, k = {}, 0
    for f in FLAGS:
        if flags[f]:
            cols[f] = rec[:, k:k + COLUMNS[f]]
            k += COLUMNS[f]
    photometric = bool(flags["luminous_flux"])
    flux = (cols["luminous_flux"] if photometric else cols["radiant_flux"])[:, 0]
    _check_rays(cols["position"], cols["direction"], flux, path)
    return RayFile(positions=np.ascontiguousarray(cols["position"]),
                   directions=np.ascontiguousarray(cols["direction"]),
                   flux=np.ascontiguousarray(flux), photometric=photometric,
                   luminous_flux=float(phi_v), radiant_flux=float(phi_e),
                   wavelengths=(np.ascontiguousarray(cols["wavelength"][:, 0])
                                if flags["wavelength"] else None),
                   radiant=(np.ascontiguousarray(cols["radiant_flux"][:, 0])
                            if flags["radiant_flux"] else None),
                   descriptions=texts, creation_method=int(method),
                   date=date.split(b"\0", 1)[0].decode("ascii", errors="replace"),
                   spectral_id=int(spectral),
                   extra={"wavelength_range_nm": (float(wl_lo), float(wl_hi))})


def _check_rays(positions: np.ndarray, directions: np.ndarray, flux: np.ndarray,
                path: str) -> None:
    """Raise naming the first ray whose start point, direction or flux cannot be traced:
    not finite, a direction of zero length, a negative flux."""
    with np.errstate(all="ignore"):
        length = np.sqrt(np.sum(directions.astype(np.float64) ** 2, axis=1))
    problems = (
        (~np.isfinite(positions).all(axis=1), "a start point that is not finite"),
        (~np.isfinite(directions).all(axis=1), "a direction that is not finite"),
        (length == 0, "a direction of zero length"),
        (~np.isfinite(flux) | (flux < 0), "a flux that is negative or not finite"),
    )
    for bad, what in problems:
        if bad.any():
            first = int(np.argmax(bad))
            raise _error(f"ray {first} (of {len(flux)}; {int(bad.sum())} such) has {what}", path)


def format_tm25(rays: RayFile) -> bytes:
    """The bytes of a photometric TM-25-13 file of ``rays``: positions, directions and
    luminous flux per ray, and, where ``rays`` has wavelengths (with radiant flux), per-ray
    wavelengths (spectral identifier 2)."""
    n = len(rays.flux)
    pos = np.asarray(rays.positions, np.float32).reshape(n, 3)
    dirs = np.asarray(rays.directions, np.float32).reshape(n, 3)
    flux = np.asarray(rays.flux, np.float32).reshape(n, 1)
    total = float(flux.astype(np.float64).sum())
    spectral = rays.wavelengths is not None
    head = bytearray(TEXT_END + 4)
    _HEAD.pack_into(head, 0, MAGIC, VERSION, int(rays.creation_method), total,
                    float(np.sum(rays.radiant)) if spectral else float("nan"), n,
                    rays.date.encode("ascii")[:28], 0, 2 if spectral else 0, float("nan"),
                    float("nan"), float("nan"), 0, 0, 0)
    struct.pack_into("<8i", head, FLAGS_AT, 1, 1, int(spectral), int(spectral), 1, 0, 0, 0)
    for k, text in enumerate(rays.descriptions[:TEXT_FIELDS]):
        raw = text[:TEXT_CHARS - 1].encode("utf-32-le")
        head[TEXT_AT + 4 * TEXT_CHARS * k:TEXT_AT + 4 * TEXT_CHARS * k + len(raw)] = raw
    # no spectral table; no additional item names (a zero count); no additional text
    cols = [pos, dirs] + ([np.asarray(rays.radiant, np.float32).reshape(n, 1),
                           np.asarray(rays.wavelengths, np.float32).reshape(n, 1)]
                          if spectral else []) + [flux]
    body = np.hstack(cols).astype("<f4").tobytes()
    return bytes(head) + body


def write_tm25(path: str | os.PathLike, rays: RayFile) -> None:
    """Write ``rays`` as a TM-25-13 file (atomically)."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(format_tm25(rays))
