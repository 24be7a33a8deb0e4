"""The intensity map EXR: OpenEXR cube maps with lumitrace metadata.

``NAME.intensity.exr`` is a single-part scanline OpenEXR image (written by
:mod:`.exr_writer`, read by OpenEXR's own reader) in ImfEnvmap's cube map layout (see
:mod:`lumitrace.film.cubemap`): ``res`` wide, ``6 * res`` tall, header attribute ``envmap``
= ``ENVMAP_CUBE``. Channels:

``Y``
    filtered luminous intensity, cd;
``raw.Y``
    unfiltered estimate, cd;
``count``
    photons binned per texel.

All channels are stored as 32-bit FLOAT, ``count`` included: viewers and OpenImageIO
handle FLOAT channels everywhere, a float never saturates, and counts stay exact up to
2**24 per texel; above that the relative rounding (<= 6e-8) is far below the Poisson noise
``1 / sqrt(count)`` of the texel. (OpenEXR's UINT would be exact to 2**32 but then
saturates, and is poorly supported by viewers.)

Metadata is one JSON string attribute, ``lumitrace`` (the Python OpenEXR API stores header
floats as 32-bit and OpenImageIO drops custom doubles; JSON keeps float64 exactly). Scalar
top-level entries are repeated as human-readable string attributes ``lumitrace:<key>``, and
``comments`` describes the channels; the JSON attribute is the authoritative copy.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..film import cubemap
from ..errors import LumitraceError, OutputError
from .exr_writer import ENVMAP_CUBE, ENVMAP_LATLONG, holds_name, write_scanline_exr

#: Header attribute holding the metadata as a JSON object.
METADATA_ATTRIBUTE = "lumitrace"
#: Prefix of the human-readable copies of scalar metadata entries.
READABLE_PREFIX = "lumitrace:"
#: The channels of an intensity map, with their units.
CHANNEL_UNITS = {"Y": "cd", "raw.Y": "cd", "count": "photons"}
#: Channels whose values must not be negative.
NON_NEGATIVE_CHANNELS = ("count",)

_COMMENTS = ("lumitrace far-field luminous intensity, OpenEXR cube map (ImfEnvmap layout). "
             "Y: filtered intensity (cd); raw.Y: unfiltered estimate (cd); "
             "count: photons per texel. Metadata: JSON in the 'lumitrace' attribute.")


def _json_default(obj: Any) -> Any:
    """Convert numpy values (and paths) that ``json`` does not know."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def _first_bad_value(obj: Any, where: str = "") -> str | None:
    """Key path of the first non-finite float or unserialisable value in ``obj``, or None."""
    if isinstance(obj, Mapping):
        for key, value in obj.items():
            if not isinstance(key, (str, int, float, bool)) and key is not None:
                return f"{where}.{key!r}" if where else repr(key)
            found = _first_bad_value(value, f"{where}.{key}" if where else str(key))
            if found is not None:
                return found
        return None
    if isinstance(obj, (list, tuple)):
        for i, value in enumerate(obj):
            found = _first_bad_value(value, f"{where}[{i}]")
            if found is not None:
                return found
        return None
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind in "fc" and not np.isfinite(obj).all():
            return where
        if obj.dtype.kind not in "biufcU":
            return where
        return None
    if isinstance(obj, (float, np.floating)):
        return None if math.isfinite(obj) else where
    if obj is None or isinstance(obj, (str, int, bool, np.integer, np.bool_, os.PathLike)):
        return None
    return where


def metadata_json(metadata: Mapping[str, Any], path: str | os.PathLike = "") -> str:
    """Serialise ``metadata`` to the JSON stored in the header (float64 exact).

    Raises :class:`OutputError` naming the entry when a value is NaN/Inf or not
    representable in JSON. numpy scalars and arrays are converted to Python values.
    """
    if not isinstance(metadata, Mapping):
        raise OutputError("metadata must be a mapping", where=str(path) or None)
    try:  # the entry at fault is looked for only when there is one (10 ms of a run)
        return json.dumps(metadata, allow_nan=False, default=_json_default)
    except (TypeError, ValueError) as exc:
        bad = _first_bad_value(metadata)
        if bad is not None:
            raise OutputError(f"metadata entry '{bad}' is NaN, Inf or not representable in "
                              "JSON", where=str(path) or None) from None
        raise OutputError(f"metadata cannot be written as JSON: {exc}",
                          where=str(path) or None) from exc


def _prepare_channels(path, channels: Mapping[str, Any],
                      expect_shape=None) -> dict[str, np.ndarray]:
    """Validate and convert channels to C-contiguous float32 arrays of one 2D shape."""
    where = str(path)
    if not isinstance(channels, Mapping) or not channels:
        raise OutputError("no channels to write", where=where)
    out: dict[str, np.ndarray] = {}
    shape = None
    for name, data in channels.items():
        if not isinstance(name, str) or not name:
            raise OutputError(f"channel names must be non-empty strings, got {name!r}",
                              where=where)
        arr = np.asarray(data)
        if arr.dtype.kind not in "biuf":
            raise OutputError(f"channel '{name}' has non-numeric dtype {arr.dtype}", where=where)
        if arr.ndim != 2:
            raise OutputError(f"channel '{name}' must be a 2D image, got shape {arr.shape}",
                              where=where)
        if shape is None:
            shape = arr.shape
        elif arr.shape != shape:
            raise OutputError(f"channel '{name}' has shape {arr.shape}, other channels "
                              f"{shape}", where=where)
        if expect_shape is not None:
            expect_shape(name, arr.shape)
        with np.errstate(over="ignore"):
            f32 = np.ascontiguousarray(arr, dtype=np.float32)
        finite = np.isfinite(f32)
        if not finite.all():
            row, col = np.argwhere(~finite)[0]
            n_bad = int((~finite).sum())
            raise OutputError(
                f"channel '{name}' has {n_bad} NaN or Inf value(s) (in float32), first at "
                f"row {row}, column {col}", where=where)
        if name in NON_NEGATIVE_CHANNELS and (f32 < 0).any():
            row, col = np.argwhere(f32 < 0)[0]
            raise OutputError(f"channel '{name}' has negative values, first at row {row}, "
                              f"column {col}", where=where)
        out[name] = f32
    return out


def _readable_attributes(metadata: Mapping[str, Any]) -> dict[str, str]:
    """String copies of the scalar entries, where an OpenEXR attribute's name can hold the
    key (the JSON attribute holds every entry)."""
    attrs = {}
    for key, value in metadata.items():
        if isinstance(value, (np.generic,)):
            value = value.item()
        if isinstance(value, (str, bool, int, float)) and isinstance(key, str) \
                and holds_name(READABLE_PREFIX + key):
            attrs[READABLE_PREFIX + key] = value if isinstance(value, str) else json.dumps(value)
    return attrs


def _write(path, strings: dict[str, str], channels: dict[str, np.ndarray],
           envmap: int) -> None:
    try:
        write_scanline_exr(path, channels, strings, envmap)
    except OutputError:
        raise
    except (OSError, ValueError) as exc:  # the file system; a name the format cannot hold
        raise OutputError(f"cannot write the OpenEXR file: {exc}", where=str(path)) from exc


def write_intensity_exr(path: str | os.PathLike, channels: Mapping[str, np.ndarray],
                        metadata: Mapping[str, Any]) -> None:
    """Write an intensity cube map EXR atomically.

    Parameters
    ----------
    path : path-like
        Target file (``NAME.intensity.exr``); written to a temporary file beside it and
        renamed, so readers see the old file or the new one, never half of one.
    channels : mapping of str to array_like, each shape (6 * res, res)
        Channel name to image (``Y``, ``raw.Y`` in cd, ``count`` in photons; others are
        allowed). Any real dtype; stored as 32-bit FLOAT. Rows and columns follow
        :mod:`lumitrace.film.cubemap` (``image[row, col]``, faces stacked top to bottom).
    metadata : mapping
        JSON-serialisable (numpy scalars and arrays allowed), without NaN/Inf; stored as
        the JSON string attribute ``lumitrace``.

    Raises
    ------
    OutputError
        Naming the channel (or metadata entry) for bad shapes, NaN/Inf (also values that
        overflow float32), negative counts; or when the file cannot be written. An existing
        file at ``path`` is then left untouched.
    """
    def cube_shape(name, shape):
        height, width = shape
        if height < 6 or height % 6 or width != height // 6:
            raise OutputError(f"channel '{name}' must be a cube map of shape (6*res, res), "
                              f"got {shape}", where=str(path))

    data = _prepare_channels(path, channels, cube_shape)
    strings = {
        "comments": _COMMENTS,
        **_readable_attributes(metadata if isinstance(metadata, Mapping) else {}),
        METADATA_ATTRIBUTE: metadata_json(metadata, path),
    }
    _write(path, strings, data, ENVMAP_CUBE)


def read_intensity_exr(path: str | os.PathLike
                       ) -> tuple[dict[str, np.ndarray], dict[str, Any], dict[str, Any]]:
    """Read an intensity cube map EXR.

    Returns
    -------
    channels : dict of str to ndarray, each shape (6 * res, res)
        FLOAT and HALF channels as float32 (bit-exact for FLOAT), UINT channels as float64.
    metadata : dict
        The parsed ``lumitrace`` JSON attribute (``{}`` if the file has none).
    header : dict
        The full OpenEXR header as the Python OpenEXR API returns it.

    Raises
    ------
    LumitraceError
        Naming the file, when it is missing, not an OpenEXR file, not a cube map
        (``envmap`` must be CUBE, shape ``6 * res`` by ``res``) or its metadata is not a
        JSON object.
    """
    where = str(path)
    if not Path(path).is_file():
        raise LumitraceError("intensity map not found", where=where)
    import OpenEXR  # read by OpenEXR's own reader

    try:
        exr = OpenEXR.File(str(path), separate_channels=True)
        header = dict(exr.header())
        raw = exr.channels()
    except Exception as exc:
        raise LumitraceError(f"not a readable OpenEXR file ({exc})", where=where) from exc
    envmap = header.get("envmap")
    if envmap != ENVMAP_CUBE:
        raise LumitraceError(f"not a cube map: header attribute envmap is {envmap!r}, "
                             "expected CUBE", where=where)
    channels: dict[str, np.ndarray] = {}
    for name, channel in raw.items():
        pixels = np.asarray(channel.pixels)
        if pixels.dtype == np.float16:
            pixels = pixels.astype(np.float32)
        elif pixels.dtype.kind in "iu":
            pixels = pixels.astype(np.float64)
        try:
            res = cubemap.face_size(pixels.shape[0])
        except ValueError:
            res = -1
        if pixels.ndim != 2 or pixels.shape[1] != res:
            raise LumitraceError(f"channel '{name}' is not a (6*res, res) cube map image: "
                                 f"shape {pixels.shape}", where=where)
        channels[name] = pixels
    text = header.get(METADATA_ATTRIBUTE)
    if text is None:
        metadata: dict[str, Any] = {}
    else:
        try:
            metadata = json.loads(text)
        except (TypeError, ValueError) as exc:
            raise LumitraceError(f"header attribute '{METADATA_ATTRIBUTE}' is not valid JSON "
                                 f"({exc})", where=where) from exc
        if not isinstance(metadata, dict):
            raise LumitraceError(f"header attribute '{METADATA_ATTRIBUTE}' is not a JSON "
                                 "object", where=where)
    return channels, metadata, header


def cube_to_latlong(image, height: int | None = None, weld: bool = True) -> np.ndarray:
    """Resample a cube map to a lat-long map (ImfEnvmap ``LatLongMap`` layout).

    Parameters
    ----------
    image : array_like, shape (6 * res, res) or (6 * res, res, C)
    height : int, optional
        Rows of the lat-long map (default ``2 * res``); it is ``2 * height`` wide.
    weld : bool
        Merge the cube's shared edge texels first (:func:`lumitrace.film.cubemap.weld_seams`)
        so that the result is continuous across the cube's edges.

    Returns
    -------
    ndarray, shape (height, 2 * height) or (height, 2 * height, C), float64
        Bilinearly interpolated values at the lat-long pixel directions.
    """
    img = np.asarray(image, dtype=np.float64)
    res = cubemap.face_size(img.shape[0])
    height = 2 * res if height is None else int(height)
    if weld:
        img = cubemap.weld_seams(img)
    dirs = cubemap.latlong_directions(height)
    out = cubemap.sample_map(img, dirs.reshape(-1, 3))
    return out.reshape(dirs.shape[:2] + img.shape[2:])


def write_latlong_exr(path: str | os.PathLike, channels, metadata: Mapping[str, Any] | None = None,
                      height: int | None = None) -> None:
    """Write a lat-long copy of a cube map, for tools that cannot read cube maps.

    The copy follows ImfEnvmap's ``LatLongMap`` (header ``envmap`` = LATLONG; first row
    +Y, centre column +Z, longitude +pi/2 at +X) in the same axes as the cube map: no
    axis is swapped, so a Z-up stage keeps its zenith at +Z. Values are interpolated
    (meaningful for intensities, not for per-texel photon counts).

    Parameters
    ----------
    path : path-like
        Target file, written atomically.
    channels : array_like (6 * res, res), or mapping of str to such arrays
        A single array is written as channel ``Y``.
    metadata : mapping, optional
        Stored as the ``lumitrace`` JSON attribute, like the cube map's.
    height : int, optional
        Rows of the lat-long map (default ``2 * res``; width ``2 * height``).

    Raises
    ------
    OutputError
        As :func:`write_intensity_exr`.
    """
    if not isinstance(channels, Mapping):
        channels = {"Y": channels}
    cube = _prepare_channels(path, channels, None)
    try:
        latlong = {name: cube_to_latlong(data, height) for name, data in cube.items()}
    except ValueError as exc:
        raise OutputError(f"channels must be cube map images (6*res, res): {exc}",
                          where=str(path)) from exc
    data = _prepare_channels(path, latlong, None)
    metadata = dict(metadata or {})
    strings = {
        "comments": "lumitrace far-field luminous intensity, lat-long copy of the cube map "
                    "(ImfEnvmap LatLongMap layout, bilinear resampling).",
        **_readable_attributes(metadata),
        METADATA_ATTRIBUTE: metadata_json(metadata, path),
    }
    _write(path, strings, data, ENVMAP_LATLONG)


__all__ = ["METADATA_ATTRIBUTE", "CHANNEL_UNITS", "write_intensity_exr", "read_intensity_exr",
           "metadata_json", "cube_to_latlong", "write_latlong_exr"]


def read_exr_metadata(path: str | os.PathLike) -> dict[str, Any] | None:
    """The ``lumitrace`` JSON metadata of an EXR file from its header alone (no pixels);
    None when the file is missing, unreadable or carries none."""
    import OpenEXR

    try:
        header = OpenEXR.File(str(path), header_only=True).header()
        meta = json.loads(header.get(METADATA_ATTRIBUTE) or "null")
    except Exception:  # noqa: BLE001 (any unreadable file: no metadata)
        return None
    return meta if isinstance(meta, dict) else None
