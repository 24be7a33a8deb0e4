"""OpenEXR files written with numpy and zlib alone: single-part scanline images and tiled,
mip-mapped ones, FLOAT channels, ZIP-compressed, as OpenEXR's file layout document gives
them.

OpenEXR's Python API writes only the first level of a multi-resolution file, and
OpenImageIO's texture maker costs a run about 0.1 s and 35 MB to load for one small
texture; a scanline image through OpenEXR's module costs a run its import (about 7 ms with
the modules its writer loads) for a write numpy and zlib do as fast. Any OpenEXR reader,
OpenImageIO's TextureSystem among them, reads every level of either.
"""
from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import numpy as np

from ..atomic import atomic_path

_MAGIC = 20000630
_TILED = 0x200  # version flag: a single-part tiled file
_LONG_NAMES = 0x400  # version flag: an attribute's or a channel's name over 31 bytes
_SHORT_NAME = 31
_LONGEST_NAME = 255  # with the long-name flag
_FLOAT = 2  # pixel type
_ZIP = 3  # compression: zlib, 16 lines (a tile is one block)
_ZIP_LINES = 16  # scanlines in a ZIP block
_MIPMAP_ROUND_DOWN = 1  # level mode MIPMAP_LEVELS + 16 * rounding mode ROUND_DOWN
ENVMAP_LATLONG = 0
ENVMAP_CUBE = 1


def mip_levels(image: np.ndarray) -> list[np.ndarray]:
    """Level 0 (``image``, float32) then each half the size (rounded down, at least 1 pixel)
    down to 1 x 1, each pixel the mean of the 2 x 2 pixels of the level above (of the 1 x 2
    or 2 x 1 once a side is 1 pixel; an odd last row or column is dropped)."""
    levels = [np.ascontiguousarray(image, dtype=np.float32)]
    while max(levels[-1].shape[:2]) > 1:
        a = levels[-1].astype(np.float64)
        h, w = a.shape[:2]
        if h > 1:
            a = 0.5 * (a[0:h - h % 2:2] + a[1:h:2])
        if w > 1:
            a = 0.5 * (a[:, 0:w - w % 2:2] + a[:, 1:w:2])
        levels.append(a.astype(np.float32))
    return levels


def _attribute(name: str, kind: str, value: bytes) -> bytes:
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def holds_name(name: str) -> bool:
    """Whether an OpenEXR file can name a channel or an attribute ``name``."""
    try:
        size = len(name.encode())
    except UnicodeEncodeError:
        return False
    return 0 < size <= _LONGEST_NAME and "\0" not in name


def _header(names: list[str], width: int, height: int, strings: dict[str, str],
            envmap: int | None, tile: int | None = None) -> bytes:
    """The magic number, version and attributes of a single-part file of FLOAT channels
    ``names`` (sorted), scanline or (``tile``) tiled and mip-mapped. ValueError for a name
    the format cannot hold."""
    for n in [*names, *strings]:
        if not holds_name(n):
            raise ValueError(f"an OpenEXR name must be 1 to {_LONGEST_NAME} bytes of "
                             f"UTF-8, without NUL: {n!r}")
    sizes = [len(n.encode()) for n in [*names, *strings]]
    chlist = b"".join(n.encode() + b"\0" + struct.pack("<iB3xii", _FLOAT, 0, 1, 1)
                      for n in names) + b"\0"
    window = struct.pack("<4i", 0, 0, width - 1, height - 1)
    attrs = [_attribute("channels", "chlist", chlist),
             _attribute("compression", "compression", bytes([_ZIP])),
             _attribute("dataWindow", "box2i", window),
             _attribute("displayWindow", "box2i", window),
             _attribute("lineOrder", "lineOrder", b"\0"),
             _attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
             _attribute("screenWindowCenter", "v2f", struct.pack("<2f", 0.0, 0.0)),
             _attribute("screenWindowWidth", "float", struct.pack("<f", 1.0))]
    if tile is not None:
        attrs.append(_attribute("tiles", "tiledesc", struct.pack("<IIB", tile, tile,
                                                                 _MIPMAP_ROUND_DOWN)))
    if envmap is not None:
        attrs.append(_attribute("envmap", "envmap", bytes([envmap])))
    attrs += [_attribute(k, "string", v.encode()) for k, v in sorted(strings.items())]
    flags = (_TILED if tile is not None else 0) | (_LONG_NAMES if max(sizes) > _SHORT_NAME
                                                    else 0)
    return struct.pack("<ii", _MAGIC, 2 | flags) + b"".join(attrs) + b"\0"


def _written(path: str | os.PathLike, head: bytes, chunks: list[bytes]) -> Path:
    """The header, the chunks' offset table and the chunks, written atomically at ``path``."""
    offsets, at = [], len(head) + 8 * len(chunks)
    for c in chunks:
        offsets.append(at)
        at += len(c)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(head + struct.pack(f"<{len(offsets)}Q", *offsets) + b"".join(chunks))
    return Path(path)


#: zlib's level for the blocks: the fastest. A map's float noise barely deflates: level 6
#: makes an intensity map 2% smaller than level 1 and takes 1.7 times as long.
ZIP_LEVEL = 1


def _zip(raw: bytes) -> bytes:
    """OpenEXR's ZIP block: bytes split into even and odd halves, delta-coded (mod 256),
    deflated; stored as they are when that is not smaller."""
    b = np.frombuffer(raw, np.uint8)
    t = np.concatenate([b[0::2], b[1::2]])
    d = np.empty_like(t)
    d[:1] = t[:1]
    np.subtract(t[1:], t[:-1], out=d[1:])
    d[1:] += 128
    packed = zlib.compress(d.tobytes(), ZIP_LEVEL)
    return packed if len(packed) < len(raw) else raw


def write_scanline_exr(path: str | os.PathLike, channels: dict[str, np.ndarray],
                       strings: dict[str, str] | None = None,
                       envmap: int | None = None) -> Path:
    """Write same-shaped 2-D images (any real dtype, stored as 32-bit FLOAT) as one
    scanline OpenEXR file in blocks of 16 lines, atomically; ``strings`` become string
    attributes, ``envmap`` the environment-map attribute (:data:`ENVMAP_CUBE`,
    :data:`ENVMAP_LATLONG`)."""
    names = sorted(channels)
    # scanline by scanline, each channel's pixels in turn (little-endian)
    lines = np.stack([np.asarray(channels[n], "<f4") for n in names], axis=1)
    height, _, width = lines.shape
    head = _header(names, width, height, strings or {}, envmap)
    chunks = []
    for y in range(0, height, _ZIP_LINES):
        data = _zip(lines[y:y + _ZIP_LINES].tobytes())
        chunks.append(struct.pack("<2i", y, len(data)) + data)
    return _written(path, head, chunks)


def write_tiled_exr(path: str | os.PathLike, channels: dict[str, np.ndarray],
                    strings: dict[str, str] | None = None, envmap: int | None = None,
                    tile: int = 64) -> Path:
    """Write same-shaped 2-D images (any real dtype, stored as 32-bit FLOAT) as one tiled,
    mip-mapped OpenEXR file, atomically; ``strings`` become string attributes, ``envmap``
    the environment-map attribute (:data:`ENVMAP_LATLONG`)."""
    names = sorted(channels)
    pyramids = [mip_levels(channels[n]) for n in names]
    height, width = pyramids[0][0].shape
    head = _header(names, width, height, strings or {}, envmap, tile)
    chunks: list[bytes] = []
    for level in range(len(pyramids[0])):
        lh, lw = pyramids[0][level].shape
        for ty in range(-(-lh // tile)):
            for tx in range(-(-lw // tile)):
                rows = slice(ty * tile, min(lh, (ty + 1) * tile))
                cols = slice(tx * tile, min(lw, (tx + 1) * tile))
                # scanline by scanline, each channel's pixels in turn (little-endian)
                block = np.stack([p[level][rows, cols] for p in pyramids], axis=1)
                data = _zip(block.astype("<f4").tobytes())
                chunks.append(struct.pack("<5i", tx, ty, level, level, len(data)) + data)
    return _written(path, head, chunks)
