"""Validation rules for what the stage reader takes from a stage.

Each rule checks one kind of value and raises :class:`~lumitrace.errors.StageError` naming
the prim and the property it came from, so the message says exactly what to fix, e.g.
``/Luminaire/Reflector.points: 3 points are NaN or infinite``. The reader calls the rules
as it reads (the first bad value stops the read; nothing is written). They are modelled on
``usdUtils.complianceChecker``: small, independent checks, one concern each.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..errors import StageError
from ..schema import (IOR, IOR_EXCLUSIVE_MIN, MATERIAL_RANGES, REFLECTANCE, SCATTERING,
                      SCATTERING_TOKENS, TRANSMITTANCE)

#: Slack allowed on ``reflectance + transmittance <= 1`` (float attributes are 32-bit).
SUM_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Sourced:
    """A value read from the stage with the prim path and property it came from."""

    value: Any
    where: str
    prop: str


#: First bytes of USD files: text, binary (crate), zip package.
USDA_SIGNATURE = b"#usda"
USDC_SIGNATURE = b"PXR-USDC"
USDZ_SIGNATURE = b"PK\x03\x04"
_SIGNATURES = {".usda": (USDA_SIGNATURE,), ".usdc": (USDC_SIGNATURE,),
               ".usd": (USDA_SIGNATURE, USDC_SIGNATURE), ".usdz": (USDZ_SIGNATURE,)}
#: Text layers larger than this are refused: USD's text parser holds all of the file in
#: memory, twice, before it finds anything wrong (a bogus 2 GiB file took 4 GiB and 6 s).
MAX_TEXT_LAYER_BYTES = 1 << 30
_SAMPLE_BYTES = 1 << 16


def check_layer_file(path) -> None:
    """A file named as a USD layer must start like one; a text layer must look like text
    (no NUL bytes in its first and last 64 KiB) and be at most :data:`MAX_TEXT_LAYER_BYTES`.

    Decided from the size and a few kilobytes, so that a huge bogus file is refused at
    once, without USD reading all of it. Other extensions are left to USD's file formats.
    """
    from pathlib import Path

    file = Path(path)
    signatures = _SIGNATURES.get(file.suffix.lower())
    if signatures is None:
        return
    where = str(file)
    try:
        size = file.stat().st_size
        with open(file, "rb") as fh:
            head = fh.read(_SAMPLE_BYTES)
            tail = b""
            if head.startswith(USDA_SIGNATURE) and size > _SAMPLE_BYTES:
                fh.seek(max(size - _SAMPLE_BYTES, _SAMPLE_BYTES))
                tail = fh.read(_SAMPLE_BYTES)
    except OSError as exc:
        raise StageError(f"cannot read: {exc.strerror or exc}", where) from exc
    if size == 0:
        raise StageError("empty file, not a USD stage", where)
    if not head.startswith(signatures):
        expected = " or ".join(repr(sig.decode("latin-1")) for sig in signatures)
        raise StageError(f"not a USD file: a {file.suffix} file starts with {expected}", where)
    if head.startswith(USDA_SIGNATURE):
        if b"\0" in head or b"\0" in tail:
            raise StageError("not a USD text layer: it holds binary data (NUL bytes)", where)
        if size > MAX_TEXT_LAYER_BYTES:
            raise StageError(f"text layer of {size / 2**30:.1f} GiB is larger than the "
                             f"{MAX_TEXT_LAYER_BYTES / 2**30:g} GiB a text layer may have: "
                             "save it as binary .usdc", where)
        check_utf8(file)


def check_utf8(path) -> None:
    """A text layer must be UTF-8 throughout (USD's parser rejects any other byte, even in a
    comment); the error names the line and column of the first bad byte."""
    where = str(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise StageError(f"cannot read: {exc.strerror or exc}", where) from exc
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise StageError(f"line {line}, column {column}: byte 0x{data[exc.start]:02x} is not "
                         "UTF-8 (a text layer must be UTF-8 throughout, comments included)",
                         where) from None


def check_stage_units(meters_per_unit: float, where: str) -> None:
    """``metersPerUnit`` must be a finite number > 0."""
    if not _is_number(meters_per_unit) or not math.isfinite(meters_per_unit) \
            or meters_per_unit <= 0.0:
        raise StageError(f"must be a finite number > 0, got {meters_per_unit!r}",
                         where, "metersPerUnit")


def check_up_axis(up_axis: str, where: str) -> None:
    """``upAxis`` must be Y or Z."""
    if up_axis not in ("Y", "Z"):
        raise StageError(f"must be 'Y' or 'Z', got {up_axis!r}", where, "upAxis")


def check_token(value: Any, allowed, where: str, prop: str) -> str:
    """A token must be one of ``allowed`` (USD does not enforce ``allowedTokens``)."""
    if not isinstance(value, str) or value not in allowed:
        raise StageError(f"unknown token {value!r}: allowed are {', '.join(allowed)}",
                         where, prop)
    return value


def check_array(value, where: str, prop: str, dtype=np.float64, width: int | None = None
                ) -> np.ndarray:
    """An array attribute's value as a numpy array ((N,) or (N, width)); no value gives an
    empty one. A value of another type (an unknown type name in the file, text) is a
    StageError naming the prim and property."""
    if value is None:
        return np.zeros((0, width) if width else 0, dtype=dtype)
    try:
        arr = np.asarray(value, dtype=dtype)
        arr = arr.reshape(-1, width) if width else arr.reshape(-1)
        if not width and np.ndim(value) != 1:
            raise ValueError(value)
    except (TypeError, ValueError, OverflowError):
        kind = f"{width}-component vectors" if width else "numbers"
        raise StageError(f"expected an array of {kind}, got {type(value).__name__}",
                         where, prop) from None
    return arr


def check_finite_points(points: np.ndarray, where: str, prop: str = "points",
                        what: str = "points") -> None:
    """Every coordinate of an (N, 3) array must be finite."""
    bad = ~np.isfinite(points).all(axis=-1)
    count = int(np.count_nonzero(bad))
    if count:
        noun = what if count != 1 else what.rstrip("s")
        verb = "are" if count != 1 else "is"
        raise StageError(f"{count} {noun} {verb} NaN or infinite", where, prop)


#: Largest distance from the origin, in metres, of anything the tracer is given: far
#: beyond any luminaire, and small enough that differences and squares of coordinates stay
#: finite in float64.
MAX_EXTENT_METRES = 1e150


def check_extent(values: np.ndarray, where: str, prop: str) -> None:
    """World coordinates (m) must be finite and within :data:`MAX_EXTENT_METRES`."""
    with np.errstate(invalid="ignore"):
        worst = float(np.max(np.abs(values))) if np.size(values) else 0.0
    if not worst <= MAX_EXTENT_METRES:  # also NaN and Inf
        raise StageError(f"reaches {worst:g} m from the origin in world metres, beyond the "
                         f"{MAX_EXTENT_METRES:g} m lumitrace traces (metersPerUnit or the "
                         "transforms are too large)", where, prop)


def check_finite_matrix(matrix: np.ndarray, where: str, prop: str) -> None:
    """A transform must have finite entries."""
    if not np.isfinite(matrix).all():
        raise StageError("transform is NaN or infinite", where, prop)


def check_face_topology(counts: np.ndarray, indices: np.ndarray, n_points: int,
                        where: str) -> None:
    """``faceVertexCounts`` must add up to the number of ``faceVertexIndices``, which must
    index ``points``."""
    if counts.size and counts.min() < 0:
        raise StageError("negative face vertex count", where, "faceVertexCounts")
    if int(counts.sum()) != indices.size:
        raise StageError(f"counts add up to {int(counts.sum())} but faceVertexIndices has "
                         f"{indices.size} entries", where, "faceVertexCounts")
    if indices.size and (indices.min() < 0 or indices.max() >= n_points):
        bad = int(np.count_nonzero((indices < 0) | (indices >= n_points)))
        raise StageError(f"{bad} indices are outside the {n_points} points", where,
                         "faceVertexIndices")


def check_number(value: Any, where: str, prop: str) -> float:
    """The value must be a real number (not None, text or a vector); returns it as float."""
    if not _is_number(value):
        raise StageError(f"expected a number, got {value!r}", where, prop)
    return float(value)


def check_finite(value: Any, where: str, prop: str) -> float:
    """The value must be a finite real number."""
    v = check_number(value, where, prop)
    if not math.isfinite(v):
        raise StageError(f"must be finite, got {v}", where, prop)
    return v


def check_positive(value: Any, where: str, prop: str, unit: str = "") -> float:
    """The value must be finite and > 0."""
    v = check_finite(value, where, prop)
    if v <= 0.0:
        raise StageError(f"must be > 0{unit}, got {v:g}", where, prop)
    return v


def check_non_negative(value: Any, where: str, prop: str) -> float:
    """The value must be finite and >= 0."""
    v = check_finite(value, where, prop)
    if v < 0.0:
        raise StageError(f"must be >= 0, got {v:g}", where, prop)
    return v


#: Largest luminous flux (lm) of one light, and of a whole luminaire, lumitrace traces.
#: Far beyond any luminaire (the brightest lamps emit some 1e6 lm), and small enough that
#: the outputs, which store intensities in cd as float32 (largest 3.4e38), stay finite:
#: all of it into one steradian is 1e24 cd, all of it into the smallest texel of a cube
#: map of 1024 x 1024 texels per face (7.3e-7 sr, at a face's corner) is 1.4e30 cd.
MAX_LUMINOUS_FLUX = 1e24
#: The limit as checked: 1e24 as a float attribute holds it (float32, 1.00000001e24) passes.
_FLUX_LIMIT = max(MAX_LUMINOUS_FLUX, float(np.float32(MAX_LUMINOUS_FLUX)))


def check_flux_limit(flux: float, where: str, prop: str | None, what: str = "luminous flux"
                     ) -> float:
    """A luminous flux (lm) must be at most :data:`MAX_LUMINOUS_FLUX` (also false for NaN
    and Inf); ``what`` says which flux, for the message."""
    if not flux <= _FLUX_LIMIT:
        raise StageError(f"{what} of {flux:g} lm is above the {MAX_LUMINOUS_FLUX:g} lm "
                         "lumitrace can trace (intensities would not fit the outputs)",
                         where, prop)
    return flux


def check_luminous_flux(value: Any, where: str, prop: str) -> float:
    """An authored luminous flux must be finite, > 0 and at most
    :data:`MAX_LUMINOUS_FLUX` (lm)."""
    return check_flux_limit(check_positive(value, where, prop, unit=" lm"), where, prop)


def check_total_flux(fluxes, where: str) -> float:
    """The luminous flux of all emitters together (lm) must be at most
    :data:`MAX_LUMINOUS_FLUX`; ``where`` is the luminaire prim."""
    total = float(sum(fluxes))  # inf on overflow, refused below
    return check_flux_limit(total, where, None,
                            f"total luminous flux of its {len(fluxes)} emitters")


def check_material(values: Mapping[str, Sourced]) -> None:
    """Check a material's resolved values, keyed by lumitrace attribute name.

    - ``lumitrace:scattering`` is one of :data:`lumitrace.schema.SCATTERING_TOKENS`
      (USD does not enforce ``allowedTokens``);
    - reflectance, specular reflectance, transmittance and roughness are in [0, 1];
    - ``lumitrace:ior`` is finite and > 0;
    - a translucent material has reflectance + transmittance <= 1.
    """
    scattering = values[SCATTERING]
    if not isinstance(scattering.value, str) or scattering.value not in SCATTERING_TOKENS:
        raise StageError(f"unknown scattering {scattering.value!r}: allowed are "
                         f"{', '.join(SCATTERING_TOKENS)}", scattering.where, scattering.prop)
    for name, (low, high) in MATERIAL_RANGES.items():
        item = values[name]
        v = check_number(item.value, item.where, item.prop)
        if not (low <= v <= high):  # also false for NaN
            raise StageError(f"must be in [{low:g}, {high:g}], got {v:g}", item.where, item.prop)
    ior = values[IOR]
    v = check_finite(ior.value, ior.where, ior.prop)
    if v <= IOR_EXCLUSIVE_MIN:
        raise StageError(f"must be > {IOR_EXCLUSIVE_MIN:g}, got {v:g}", ior.where, ior.prop)
    if scattering.value == "translucent":
        r, t = values[REFLECTANCE], values[TRANSMITTANCE]
        total = float(r.value) + float(t.value)
        if total > 1.0 + SUM_TOLERANCE:
            raise StageError(f"{REFLECTANCE} + {TRANSMITTANCE} = {total:g} exceeds 1 for a "
                             "translucent material", t.where, t.prop)


def _is_number(value: Any) -> bool:
    if isinstance(value, (bool, np.bool_, str, bytes)) or value is None:
        return False
    return isinstance(value, numbers.Real)
