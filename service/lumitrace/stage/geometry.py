"""Gprims to triangles in their local space: ``UsdGeom.Mesh`` polygons fan-triangulated,
implicit gprims tessellated, front faces made counter-clockwise, the dielectric faces of a
closed surface made to face the air; and the test for zero-area triangles."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from pxr import Usd, UsdGeom

from . import validate
from .materials import BoundMaterials
from .reuse import ReadCache
from .validate import check_array

#: Tessellation of implicit gprims: segments around, rings from pole to pole.
TESSELLATION_SEGMENTS = 64
TESSELLATION_RINGS = 32

#: A triangle is dropped when |e1 x e2| <= this * (longest edge)^2.
DEGENERATE_TOLERANCE = 1e-10

_IMPLICIT_GPRIMS = ("Cube", "Sphere", "Cylinder", "Cone", "Plane")
_ORIENTATIONS = (UsdGeom.Tokens.rightHanded, UsdGeom.Tokens.leftHanded)
_AXES = ("X", "Y", "Z")


@dataclass
class LocalMesh:
    """A gprim's triangles in its local space, before placement."""

    triangles: np.ndarray        # (T, 3, 3) float64, local units, front faces CCW
    material_index: np.ndarray   # (T,) int32


def local_mesh(prim: Usd.Prim, time: Usd.TimeCode, materials: BoundMaterials,
               warn: Callable[[str], None], cache: ReadCache | None = None
               ) -> LocalMesh | None:
    """The triangles of a gprim and their materials (bound into ``materials``), or None
    (with a warning) when it has nothing to trace; a mesh's triangulation taken from
    ``cache`` where an earlier read made it of the same arrays."""
    path = str(prim.GetPath())
    type_name = str(prim.GetTypeName())
    if prim.IsA(UsdGeom.Mesh):
        polygons = _mesh_polygons(prim, time, warn)
    elif type_name in _IMPLICIT_GPRIMS:
        polygons = _implicit_polygons(prim, time)
    else:
        warn(f"{path}: {type_name or 'untyped gprim'} is not a surface lumitrace "
             "traces (Mesh, Cube, Sphere, Cylinder, Cone, Plane are): skipped")
        return None
    if polygons is None:
        return None
    points, counts, indices, keep_face = polygons
    orientation = validate.check_token(UsdGeom.Gprim(prim).GetOrientationAttr().Get(time),
                                       _ORIENTATIONS, path, "orientation")

    def triangulated():
        triangles, face = _triangulate(points, counts, indices, keep_face)
        if orientation == UsdGeom.Tokens.leftHanded:
            triangles = triangles[:, [0, 2, 1]]
        return triangles, face

    if cache is not None and prim.IsA(UsdGeom.Mesh):
        triangles, face_of_triangle = cache.triangulated(
            path, (points, counts, indices, keep_face, str(orientation)), triangulated)
    else:
        triangles, face_of_triangle = triangulated()
    if len(triangles) == 0:
        warn(f"{path}: no faces: skipped")
        return None
    face_material = materials.face_materials(prim, counts.size)
    material_index = face_material[face_of_triangle].astype(np.int32)
    dielectric = np.array([m.scattering == "dielectric" for m in materials.materials],
                          dtype=bool)[material_index]
    if dielectric.any():
        triangles = _orient_dielectric(path, triangles, dielectric, warn)
    return LocalMesh(triangles, material_index)


def _orient_dielectric(path: str, triangles: np.ndarray, dielectric: np.ndarray,
                       warn: Callable[[str], None]) -> np.ndarray:
    """Make the dielectric faces of a gprim face the air.

    The tracer tells the inside of a dielectric from the winding (front = outside). When
    the dielectric faces form a closed, consistently wound surface, its signed volume
    says which way they face: a negative volume means they all point inward (a mesh
    exported with flipped normals), and they are flipped, with a warning. The volume of
    the whole surface is used, so a hollow part, whose inner surface rightly faces its
    cavity, keeps its orientation. A surface that is open or inconsistently wound cannot
    be judged: a warning says its winding is taken as it is.
    """
    faces = triangles[dielectric]
    closed, volume = _closed_surface_volume(faces)
    if not closed:
        warn(f"{path}: dielectric faces do not form a closed, consistently wound "
             "surface: their inside is taken from the winding (counter-clockwise "
             "= outside)")
    elif volume < 0.0:
        warn(f"{path}: the closed dielectric surface faces inward (negative "
             "volume, normals flipped): its faces are flipped to face the air")
        triangles = triangles.copy()
        triangles[dielectric] = faces[:, [0, 2, 1]]
    return triangles


def _mesh_polygons(prim: Usd.Prim, time: Usd.TimeCode, warn: Callable[[str], None]):
    path = str(prim.GetPath())
    mesh = UsdGeom.Mesh(prim)
    points = check_array(mesh.GetPointsAttr().Get(time), path, "points", width=3)
    if len(points) == 0:
        warn(f"{path}: mesh has no points: skipped")
        return None
    validate.check_finite_points(points, path, "points")
    scheme = mesh.GetSubdivisionSchemeAttr()
    if scheme.HasAuthoredValue() and scheme.Get() != UsdGeom.Tokens.none:
        warn(f"{path}: subdivisionScheme is {scheme.Get()!r}: traced as its control cage "
             "(renderers would subdivide it); author subdivisionScheme = \"none\" or "
             "export the refined mesh")
    counts = check_array(mesh.GetFaceVertexCountsAttr().Get(time), path,
                         "faceVertexCounts", np.int64)
    indices = check_array(mesh.GetFaceVertexIndicesAttr().Get(time), path,
                          "faceVertexIndices", np.int64)
    validate.check_face_topology(counts, indices, len(points), path)
    keep_face = counts >= 3
    small = int(counts.size - np.count_nonzero(keep_face))
    if small:
        warn(f"{path}: {small} face(s) with fewer than 3 vertices ignored")
    holes = check_array(mesh.GetHoleIndicesAttr().Get(time), path, "holeIndices", np.int64)
    if holes.size:
        valid = holes[(holes >= 0) & (holes < counts.size)]
        keep_face[valid] = False
    return points, counts, indices, keep_face


def _triangulate(points: np.ndarray, counts: np.ndarray, indices: np.ndarray,
                 keep_face: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate polygons: (T, 3, 3) triangles and the face each one came from."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    per_face = np.where(keep_face, np.maximum(counts - 2, 0), 0)
    face = np.repeat(np.arange(counts.size), per_face)
    k = np.arange(face.size) - np.repeat(np.cumsum(per_face) - per_face, per_face)
    first = starts[face]
    corners = np.stack([indices[first], indices[first + k + 1], indices[first + k + 2]],
                       axis=1)
    return points[corners], face


def _closed_surface_volume(triangles: np.ndarray) -> tuple[bool, float]:
    """Whether triangles (T, 3, 3) form closed, consistently wound surfaces, and their
    signed volume (positive when the counter-clockwise fronts face outward).

    Corners are matched by position (exports often split vertices along seams). Closed and
    consistent: every directed edge occurs exactly once, and so does its reverse; triangles
    with a repeated corner have no area and are ignored.
    """
    corners = np.ascontiguousarray(triangles.reshape(-1, 3), dtype=np.float64) + 0.0  # -0 -> 0
    keys = corners.view(np.dtype((np.void, corners.dtype.itemsize * 3))).ravel()
    _, vertex = np.unique(keys, return_inverse=True)
    vertex = vertex.reshape(-1, 3).astype(np.int64)
    a, b, c = vertex.T
    proper = (a != b) & (b != c) & (c != a)
    a, b, c = a[proper], b[proper], c[proper]
    if a.size == 0:
        return False, 0.0
    n = int(vertex.max()) + 1
    edges = np.concatenate([a * n + b, b * n + c, c * n + a])
    reverse = np.concatenate([b * n + a, c * n + b, a * n + c])
    edges.sort()
    reverse.sort()
    closed = bool(np.all(edges[1:] != edges[:-1]) and np.array_equal(edges, reverse))
    tri = triangles[proper] - corners.mean(axis=0)
    volume = float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()) / 6.0
    return closed, volume


def non_degenerate(triangles: np.ndarray) -> np.ndarray:
    """Mask of triangles with a non-zero area (relative to their longest edge), at any
    scale: edges are scaled by a power of two to a largest coordinate near 1 before squaring,
    so that triangles of 1e-200 m do not underflow nor those of 1e200 m overflow. (On
    coordinate rows, (3, T): a million triangles in a third of the time of whole-array
    cross products and norms.)"""
    t = np.asarray(triangles, np.float64)
    a, b, c = (np.ascontiguousarray(t[:, k].T) for k in range(3))
    e1, e2 = b - a, c - a
    size = np.maximum(np.abs(e1).max(axis=0), np.abs(e2).max(axis=0))
    ok = (size > 0.0) & np.isfinite(size)
    _, exponent = np.frexp(np.where(ok, size, 1.0))
    e1 = np.ldexp(np.where(ok, e1, 0.0), -exponent)  # exact powers of 2
    e2 = np.ldexp(np.where(ok, e2, 0.0), -exponent)
    e3 = e2 - e1
    cx = e1[1] * e2[2] - e1[2] * e2[1]
    cy = e1[2] * e2[0] - e1[0] * e2[2]
    cz = e1[0] * e2[1] - e1[1] * e2[0]
    cross = np.sqrt(cx * cx + cy * cy + cz * cz)
    longest = np.maximum(np.maximum(*(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]
                                      for e in (e1, e2))), e3[0] * e3[0] + e3[1] * e3[1]
                         + e3[2] * e3[2])
    return ok & (cross > DEGENERATE_TOLERANCE * longest)


def _axis_permutation(axis: str) -> list[int]:
    """Column order mapping shapes built along +Z onto ``axis`` (a rotation, so
    right-handedness is kept)."""
    return {"X": [2, 0, 1], "Y": [1, 2, 0], "Z": [0, 1, 2]}[axis]


def _implicit_polygons(prim: Usd.Prim, time: Usd.TimeCode):
    """Points, face counts, indices and kept faces of an implicit gprim, outward faces CCW."""
    path = str(prim.GetPath())
    type_name = str(prim.GetTypeName())
    n = TESSELLATION_SEGMENTS
    phi = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    ring = np.arange(n)
    nxt = (ring + 1) % n
    if type_name == "Cube":
        size = validate.check_positive(UsdGeom.Cube(prim).GetSizeAttr().Get(time), path, "size")
        h = 0.5 * size
        points = np.array([[x, y, z] for z in (-h, h) for y in (-h, h) for x in (-h, h)])
        quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2],
                 [1, 3, 7, 5]]
        return _polygons(points, quads)
    if type_name == "Sphere":
        r = validate.check_positive(UsdGeom.Sphere(prim).GetRadiusAttr().Get(time), path,
                                    "radius")
        rings = TESSELLATION_RINGS
        theta = np.linspace(0.0, math.pi, rings + 1)[1:-1]
        grid = np.stack([np.outer(np.sin(theta), np.cos(phi)),
                         np.outer(np.sin(theta), np.sin(phi)),
                         np.outer(np.cos(theta), np.ones(n))], axis=-1).reshape(-1, 3)
        points = r * np.vstack([[0.0, 0.0, 1.0], grid, [0.0, 0.0, -1.0]])
        south = len(points) - 1
        faces = [[0, 1 + i, 1 + j] for i, j in zip(ring, nxt)]
        for band in range(rings - 2):
            a, b = 1 + band * n, 1 + (band + 1) * n
            faces += [[a + i, b + i, b + j, a + j] for i, j in zip(ring, nxt)]
        last = 1 + (rings - 2) * n
        faces += [[south, last + j, last + i] for i, j in zip(ring, nxt)]
        return _polygons(points, faces)
    if type_name in ("Cylinder", "Cone"):
        schema_ = UsdGeom.Cylinder(prim) if type_name == "Cylinder" else UsdGeom.Cone(prim)
        r = validate.check_positive(schema_.GetRadiusAttr().Get(time), path, "radius")
        height = validate.check_positive(schema_.GetHeightAttr().Get(time), path, "height")
        axis = validate.check_token(schema_.GetAxisAttr().Get(time), _AXES, path, "axis")
        circle = np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
        bottom = np.column_stack([circle, np.full(n, -0.5 * height)])
        if type_name == "Cylinder":
            top = np.column_stack([circle, np.full(n, 0.5 * height)])
            points = np.vstack([bottom, top])
            faces = [[i, j, n + j, n + i] for i, j in zip(ring, nxt)]
            faces += [list(n + ring), list(ring[::-1])]
        else:
            points = np.vstack([bottom, [[0.0, 0.0, 0.5 * height]]])
            faces = [[i, j, n] for i, j in zip(ring, nxt)]
            faces += [list(ring[::-1])]
        return _polygons(points[:, _axis_permutation(axis)], faces)
    # Plane: a rectangle facing +axis
    plane = UsdGeom.Plane(prim)
    width = validate.check_positive(plane.GetWidthAttr().Get(time), path, "width")
    length = validate.check_positive(plane.GetLengthAttr().Get(time), path, "length")
    axis = validate.check_token(plane.GetAxisAttr().Get(time), _AXES, path, "axis")
    # UsdGeomPlane: width along x (z when axis is X), length along y (z when axis is Y).
    w, l = 0.5 * width, 0.5 * length
    corners = {"X": [[0, -l, -w], [0, l, -w], [0, l, w], [0, -l, w]],
               "Y": [[-w, 0, -l], [w, 0, -l], [w, 0, l], [-w, 0, l]],
               "Z": [[-w, -l, 0], [w, -l, 0], [w, l, 0], [-w, l, 0]]}[axis]
    points = np.asarray(corners, dtype=np.float64)
    normal = np.cross(points[1] - points[0], points[2] - points[0])
    face = [0, 1, 2, 3] if normal["XYZ".index(axis)] > 0 else [0, 3, 2, 1]
    return _polygons(points, [face])


def _polygons(points, faces):
    counts = np.array([len(f) for f in faces], dtype=np.int64)
    indices = np.concatenate([np.asarray(f, dtype=np.int64) for f in faces])
    return np.asarray(points, dtype=np.float64), counts, indices, np.ones(counts.size, bool)
