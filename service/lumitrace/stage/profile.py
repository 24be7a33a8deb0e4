"""Parametric profiles: a mesh that carries the curve it is made from.

A ``UsdGeom.Mesh`` with ``LumitraceProfileAPI`` holds its generating profile:
``lumitrace:profile:points`` ((r, z) pairs in the mesh's local units), ``:kind``
(``revolve``: turned about the mesh's local up axis, the stage's ``upAxis``; ``extrude``:
the (x, z) polyline swept along the horizontal axis across it, ``:length`` long, centred),
and ``:segments`` (around for a revolve, along the length for an extrusion). The points
are the vertices of a polyline: a revolved profile of six points is a reflector of five
conical bands.

:func:`profile_mesh` makes the mesh's points and faces from a profile. lumitrace writes
them wherever it changes a profile (a scene delta, every fit candidate), so every DCC
sees the geometry traced; the stage reader traces the mesh's own points, validates the
profile, and warns where the two disagree (a points edit a DCC made by hand).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pxr import Usd

from .. import schema
from ..errors import StageError
from .validate import check_array

#: Segments of a revolve (around) and of an extrusion (along): the schema's fallback and
#: the limits a stage may ask for.
SEGMENTS_RANGE = {"revolve": (3, 4096), "extrude": (1, 4096)}
#: Most profile points a mesh may carry.
MAX_POINTS = 10_000
#: Authored points agree with the profile's when every coordinate is within this share of
#: the mesh's largest extent (float32 storage).
AGREEMENT = 1e-5


@dataclass(frozen=True)
class Profile:
    """A checked profile: ``points`` (P, 2) float64 (r, z) in local units, ``kind``
    (revolve or extrude), ``segments``, ``length`` (local units, extrusions) and the
    up axis it is made about."""

    points: np.ndarray
    kind: str
    segments: int
    length: float
    up_axis: str = "Z"


def has_profile(prim: Usd.Prim) -> bool:
    """Whether the prim authors a profile (its points)."""
    attr = prim.GetAttribute(schema.PROFILE_POINTS)
    return bool(attr) and attr.HasAuthoredValue()


def check_profile(points, kind, segments, length, where: str,
                  up_axis: str = "Z") -> Profile:
    """A :class:`Profile` of these values, or a :class:`StageError` naming the property:
    at least two finite points, no two in a row the same, no negative radius in a
    revolve, a known kind, whole segments in :data:`SEGMENTS_RANGE`, an extrusion's length
    finite and > 0."""
    pts = check_array(points, where, schema.PROFILE_POINTS, width=2)
    if len(pts) < 2:
        raise StageError(f"needs at least 2 (r, z) points, got {len(pts)}", where,
                         schema.PROFILE_POINTS)
    if len(pts) > MAX_POINTS:
        raise StageError(f"has {len(pts):,} points; at most {MAX_POINTS:,}", where,
                         schema.PROFILE_POINTS)
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        raise StageError(f"point {int(np.flatnonzero(bad)[0])} is NaN or infinite", where,
                         schema.PROFILE_POINTS)
    if kind not in schema.PROFILE_KINDS:
        raise StageError(f"unknown token {kind!r}: allowed are "
                         f"{', '.join(schema.PROFILE_KINDS)}", where, schema.PROFILE_KIND)
    if kind == "revolve" and (pts[:, 0] < 0).any():
        i = int(np.flatnonzero(pts[:, 0] < 0)[0])
        raise StageError(f"point {i} has a negative radius ({pts[i, 0]:g}): a revolved "
                         "profile's r is at least 0", where, schema.PROFILE_POINTS)
    same = np.flatnonzero((np.diff(pts, axis=0) == 0).all(axis=1))
    if same.size:
        raise StageError(f"points {int(same[0])} and {int(same[0]) + 1} are the same: the "
                         "band between them would have no area", where, schema.PROFILE_POINTS)
    if isinstance(segments, bool) or not isinstance(segments, (int, np.integer)):
        raise StageError(f"must be a whole number, got {segments!r}", where,
                         schema.PROFILE_SEGMENTS)
    lo, hi = SEGMENTS_RANGE[kind]
    if not lo <= int(segments) <= hi:
        raise StageError(f"must be between {lo} and {hi} for a {kind}, got {segments}",
                         where, schema.PROFILE_SEGMENTS)
    length = float(length) if isinstance(length, (int, float, np.floating)) and \
        not isinstance(length, bool) else math.nan
    if kind == "extrude" and not (math.isfinite(length) and length > 0):
        raise StageError(f"an extrusion's length must be finite and > 0, got {length:g}",
                         where, schema.PROFILE_LENGTH)
    return Profile(pts, kind, int(segments), length, up_axis)


def read_profile(prim: Usd.Prim, time: Usd.TimeCode, up_axis: str) -> Profile:
    """The prim's profile, checked (see :func:`check_profile`)."""
    def value(name, fallback):
        attr = prim.GetAttribute(name)
        v = attr.Get(time) if attr else None
        return fallback if v is None else v

    return check_profile(value(schema.PROFILE_POINTS, None),
                         value(schema.PROFILE_KIND, schema.PROFILE_FALLBACKS[
                             schema.PROFILE_KIND]),
                         value(schema.PROFILE_SEGMENTS, schema.PROFILE_FALLBACKS[
                             schema.PROFILE_SEGMENTS]),
                         value(schema.PROFILE_LENGTH, schema.PROFILE_FALLBACKS[
                             schema.PROFILE_LENGTH]),
                         str(prim.GetPath()), up_axis)


def profile_mesh(profile: Profile) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mesh of a profile: (points (V, 3) float64, faceVertexCounts, faceVertexIndices)
    in the mesh's local units. A revolve's points on the axis (r = 0) are one vertex, its
    bands there triangles; every face is wound the same way round (only a dielectric's
    faces have a side that matters, and it is made to face the air when read)."""
    p = profile.points
    up = 2 if profile.up_axis == "Z" else 1
    across = 1 if profile.up_axis == "Z" else 2  # the horizontal axis besides X
    if profile.kind == "extrude":
        n = profile.segments + 1
        t = np.linspace(-0.5 * profile.length, 0.5 * profile.length, n)
        pts = np.zeros((len(p), n, 3))
        pts[:, :, 0] = p[:, 0, None]
        pts[:, :, up] = p[:, 1, None]
        pts[:, :, across] = t[None, :]
        idx = np.arange(len(p) * n).reshape(len(p), n)
        quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], axis=-1)
        quads = quads.reshape(-1, 4)
        return pts.reshape(-1, 3), np.full(len(quads), 4, np.int32), \
            quads.ravel().astype(np.int32)
    s = profile.segments
    phi = 2.0 * math.pi * np.arange(s) / s
    sign = 1.0 if profile.up_axis == "Z" else -1.0  # right-handed about the up axis
    points, ring = [], []
    for r, z in p:
        first = sum(len(x) for x in points)
        if r == 0.0:
            row = np.zeros((1, 3))
            row[0, up] = z
            ring.append(np.full(s, first))
        else:
            row = np.zeros((s, 3))
            row[:, 0] = r * np.cos(phi)
            row[:, across] = sign * r * np.sin(phi)
            row[:, up] = z
            ring.append(first + np.arange(s))
        points.append(row)
    counts, indices = [], []
    for i in range(len(p) - 1):
        a, b = ring[i], ring[i + 1]
        if p[i, 0] == 0.0 and p[i + 1, 0] == 0.0:
            continue  # a band along the axis has no area
        for j in range(s):
            k = (j + 1) % s
            face = [a[j], b[j], b[k], a[k]]
            if p[i, 0] == 0.0:
                face = [a[j], b[j], b[k]]
            elif p[i + 1, 0] == 0.0:
                face = [a[j], b[j], a[k]]
            counts.append(len(face))
            indices.extend(face)
    return np.concatenate(points), np.asarray(counts, np.int32), \
        np.asarray(indices, np.int32)


def mesh_agrees(profile: Profile, points: np.ndarray, counts: np.ndarray,
                indices: np.ndarray) -> bool:
    """Whether a mesh's authored arrays are those of its profile (points to
    :data:`AGREEMENT` of its extent, faces exactly)."""
    want, want_counts, want_indices = profile_mesh(profile)
    if points.shape != want.shape or not np.array_equal(counts, want_counts) or \
            not np.array_equal(indices, want_indices):
        return False
    scale = float(np.abs(want).max()) if want.size else 1.0
    return bool(np.abs(points - want).max() <= AGREEMENT * max(scale, 1e-30))
