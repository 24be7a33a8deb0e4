"""Which symmetry of type C photometry a luminaire has by its geometry alone.

A symmetry is shown, not assumed: the parts (triangles with their materials and facing),
the emitters (kind, flux, size, shaping, colour, place and facing) and their placements must
map onto themselves under the symmetry's reflections and rotations about the vertical axis
through the luminaire's centre, each point within :data:`TOLERANCE` of the luminaire's size.
No photon is needed, and nothing the photons could show is taken for granted:

- ``C0-C180``: the reflection across the C0-C180 plane (C90 coordinate negated);
- ``C90-C270``: the reflection across the C90-C270 plane (C0 coordinate negated);
- ``quadrant``: both;
- ``octant``: both and the rotation by 90 deg (a square luminaire: C and 90 - C alike);
- ``rotational``: the C0-C180 reflection and a rotation by at most :data:`ROTATION_STEP_DEG`
  (an N-fold luminaire with N >= 72: its distribution repeats at least every 5 deg of C, the
  published planes' step, so no plane the files list can differ from another), or every
  rotation where all of it lies on the axis (a point source, a disc facing down).

Emitters this cannot compare (an IES-shaped or ray-file light, a non-uniformly scaled
sphere or disc) make the geometry silent: the counts decide then.
"""
from __future__ import annotations

import math

import numpy as np

from .model import Scene

#: Points match within this share of the luminaire's largest extent.
TOLERANCE = 1e-6
#: The largest rotation (deg) that shows rotational symmetry: the C step of the files.
ROTATION_STEP_DEG = 5.0
#: Symmetries, strongest first, with the reflections each needs ("y": across the C0-C180
#: plane, "x": across the C90-C270 plane) and whether it needs the fine rotation.
NEEDS = {"rotational": ("y", "rot"), "octant": ("y", "x", "r4"), "quadrant": ("y", "x"),
         "C0-C180": ("y",), "C90-C270": ("x",)}
#: A rotation by an angle no finite pattern repeats at: tried where all lies on the axis.
_GENERIC_ANGLE_DEG = 2.718281828


class _Unsupported(Exception):
    """An emitter the geometric test cannot map (the counts decide)."""


def geometric_symmetry(scene: Scene) -> str:
    """The strongest symmetry of :data:`NEEDS` the scene maps onto itself under, or
    ``none`` (remembered for the last few scenes, by content hash)."""
    key = scene.content_hash()
    if key not in _KNOWN:
        _KNOWN[key] = _symmetry_of(scene)
        for old in list(_KNOWN)[:-8]:
            del _KNOWN[old]
    return _KNOWN[key]


#: The symmetry of the scenes tested last, by content hash.
_KNOWN: dict[str, str] = {}


def _symmetry_of(scene: Scene) -> str:
    try:
        markers = _Markers.of(scene)
    except _Unsupported:
        return "none"
    held = {"y": markers.maps_onto_itself(np.diag([1.0, -1.0, 1.0])),
            "x": markers.maps_onto_itself(np.diag([-1.0, 1.0, 1.0]))}
    if held["y"]:
        held["rot"] = markers.fine_rotation()
        if held["x"] and not held["rot"]:
            held["r4"] = markers.maps_onto_itself(_rotation(90.0))
    return next((name for name, needs in NEEDS.items() if all(held.get(n) for n in needs)),
                "none")


def _rotation(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                     [0.0, 0.0, 1.0]])


class _Markers:
    """The scene in the photometric frame, centred on the vertical axis through the middle
    of its horizontal extent: oriented triangles (parts) and emitters' descriptors, each
    with a signature of what else must match (material, emitter kind, flux, size...)."""

    def __init__(self, tri, tri_sig, emit, emit_sig, scale):
        self.tri, self.tri_sig = tri, tri_sig        # (T, 3, 3), (T,)
        self.emit, self.emit_sig = emit, emit_sig    # (E, 3, 3), (E,)
        self.tol = TOLERANCE * scale
        self._surface = None  # the triangles' flat faces and vertices, made once

    @classmethod
    def of(cls, scene: Scene) -> "_Markers":
        axes = np.asarray(scene.photometric_axes, np.float64)  # rows C0, C90, up
        pts = scene.shape_points() @ axes.T
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        centre = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.0])
        scale = float(max(np.max(hi - lo), 1e-12))
        tri = np.asarray(scene.triangles, np.float64) @ axes.T - centre
        sigs: dict = {}
        mat_sig = np.array([sigs.setdefault(("material", _material_key(m)), len(sigs))
                            for m in scene.materials] or [0], np.int64)
        tri_sig = mat_sig[np.asarray(scene.material_index, np.int64)] if len(tri) else \
            np.zeros(0, np.int64)
        emit, emit_sig = [], []
        for e in scene.emitters:
            for marker, key in _emitter_markers(e):
                emit.append(marker @ axes.T - centre)
                emit_sig.append(sigs.setdefault(("emitter", key), len(sigs)))
            if e.kind == "mesh":  # its triangles face as the surface does
                world = np.asarray(e.triangles, np.float64) + np.asarray(e.to_world)[:3, 3]
                key = ("mesh light", _emitter_key(e), bool(e.two_sided))
                t = world @ axes.T - centre
                tri = np.concatenate([tri, t]) if len(tri) else t
                tri_sig = np.concatenate([tri_sig, np.full(len(t), sigs.setdefault(
                    ("emitter", key), len(sigs)), np.int64)])
        emit = np.array(emit, np.float64).reshape(-1, 3, 3)
        return cls(tri.reshape(-1, 3, 3), tri_sig, emit, np.array(emit_sig, np.int64), scale)

    def maps_onto_itself(self, q: np.ndarray) -> bool:
        """Whether the orthogonal map ``q`` (3x3, about the centre) takes every triangle
        to a triangle of the same signature and facing, and every emitter to an emitter
        of the same signature, within the tolerance."""
        if self._surface is None:
            self._surface = (_flat_faces(self.tri, self.tri_sig, self.tol),
                             _welded(self.tri, self.tol)[0])
        return _same_surface(*self._surface, q, self.tol) and \
            _same_markers(self.emit, self.emit_sig, self.emit @ q.T, self.tol)

    def fine_rotation(self) -> bool:
        """Whether a rotation by at most :data:`ROTATION_STEP_DEG` maps the scene onto
        itself (tried at the angles that take its outermost point to a point of the
        same ring), or any rotation where everything lies on the axis."""
        pts = np.concatenate([self.tri.reshape(-1, 3), self.emit.reshape(-1, 3)])
        if not len(pts):
            return True
        rho = np.hypot(pts[:, 0], pts[:, 1])
        k = int(np.argmax(rho))
        if rho[k] <= self.tol:  # all on the axis: a generic angle shows every angle
            return self.maps_onto_itself(_rotation(_GENERIC_ANGLE_DEG))
        ring = (np.abs(rho - rho[k]) <= self.tol) & (np.abs(pts[:, 2] - pts[k, 2]) <= self.tol)
        phi = np.degrees(np.arctan2(pts[ring, 1], pts[ring, 0]) -
                         math.atan2(pts[k, 1], pts[k, 0])) % 360.0
        step = np.degrees(self.tol / rho[k])
        angles = np.unique(np.round(phi[(phi > step) & (phi <= ROTATION_STEP_DEG + step)], 9))
        return any(self.maps_onto_itself(_rotation(a)) for a in angles[:4])


def _material_key(m) -> tuple:
    """What of a material the light sees (its path aside)."""
    return (m.scattering, m.reflectance, m.specular_reflectance, m.transmittance, m.ior,
            m.roughness, m.reflectance_spectrum, m.specular_spectrum,
            m.transmittance_spectrum, m.abbe_number, m.sellmeier)


def _emitter_key(e) -> tuple:
    """What of an emitter, its place and facing aside, must match its image."""
    ies = None if e.ies is None else (e.ies.file, e.ies.angle_scale, e.ies.normalize)
    return (e.kind, e.treat_as_point, e.cone_angle, e.cone_softness, e.focus, ies, e.rays,
            e.spectrum, e.ray_bands)


def _emitter_markers(e):
    """Per light an emitter stands for: (a marker (3, 3) of world points that its image
    must reproduce as a set, a signature). The markers carry the light's place and its
    facing: a disc its centre and a point along its normal (a disc is round about it), a
    rectangle its centre and its edges' mid-points (a rectangle is its own mirror image
    across either middle), a cylinder its axis' ends, a sphere its centre."""
    if e.ies is not None or e.rays is not None:
        raise _Unsupported
    if e.kind == "mesh":
        return []
    m = np.asarray(e.to_world, np.float64)
    lin = m[:3, :3]
    cols = [lin[:, i] for i in range(3)]
    norms = [float(np.linalg.norm(c)) for c in cols]
    origins = e.light_origins()
    fluxes = e.flux * (np.asarray(e.group.shares) if e.group is not None else np.ones(1))
    out = []
    for o, flux in zip(origins, fluxes):
        flux_key = float(f"{flux:.9g}")
        if e.kind == "sphere":
            if not np.allclose(norms, norms[0], rtol=1e-9):
                raise _Unsupported
            r = 0.0 if e.treat_as_point else e.radius * norms[0]
            out.append((np.stack([o, o, o]), (_emitter_key(e), flux_key, float(f"{r:.9g}"))))
        elif e.kind == "disk":
            if abs(norms[0] - norms[1]) > 1e-9 * max(norms) or abs(cols[0] @ cols[1]) > \
                    1e-9 * norms[0] * norms[1]:
                raise _Unsupported
            r = e.radius * norms[0]
            n = -cols[2] / norms[2]  # one-sided: emits along local -Z
            out.append((np.stack([o, o, o + r * n]), (_emitter_key(e), flux_key,
                                                        float(f"{r:.9g}"))))
        elif e.kind == "rect":
            a, b = 0.5 * e.width * cols[0], 0.5 * e.height * cols[1]
            n = -np.cross(cols[0], cols[1])
            n = n / max(float(np.linalg.norm(n)), 1e-300) * max(norms[0], norms[1])
            size = tuple(sorted(float(f"{x:.9g}") for x in (np.linalg.norm(a),
                                                           np.linalg.norm(b))))
            sig = (_emitter_key(e), flux_key, size)
            # the edges' mid-points come in opposite pairs: one marker per pair, with the
            # point along the emitting side to say which way it faces
            for half in (a, b):  # tagged with its own length: a square's two are alike
                out.append((np.stack([o + half, o - half, o + n]),
                            sig + (float(f"{np.linalg.norm(half):.9g}"),)))
        elif e.kind == "cylinder":
            if abs(norms[1] - norms[2]) > 1e-9 * max(norms):
                raise _Unsupported
            a = 0.5 * e.length * cols[0]
            r = e.radius * norms[1]
            out.append((np.stack([o + a, o - a, o]), (_emitter_key(e), flux_key,
                                                        float(f"{r:.9g}"))))
        else:
            raise _Unsupported
    return out


def _pack(cells: np.ndarray) -> np.ndarray:
    """One int64 key per integer cell (N, 3) (cells span far less than 2^20 a side)."""
    c = cells + (1 << 20)
    return (c[:, 0] << 42) | (c[:, 1] << 21) | c[:, 2]


def _match(a: np.ndarray, b: np.ndarray, sig_a: np.ndarray, sig_b: np.ndarray,
           tol: float, cost=None) -> np.ndarray | None:
    """For each point of ``b`` (N, 3) the point of ``a`` (N, 3) of the same signature
    within ``tol`` (the nearest, or the one of least ``cost(ia, ib)`` among those, where
    points coincide); None unless every point of ``a`` is taken exactly once. Points are
    hashed on a grid of cells twice the tolerance: a match lies in one of the 8 cells
    around a point's corner nearest to it."""
    if len(a) != len(b):
        return None
    if not len(a):
        return np.zeros(0, np.int64)
    q = 2.0 * tol
    keys = _pack(np.floor(a / q).astype(np.int64))
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    scaled = b / q
    base = np.floor(scaled).astype(np.int64)
    side = np.where(scaled - base >= 0.5, 1, -1)
    best = np.full(len(b), -1, np.int64)
    best_cost = np.full(len(b), np.inf)
    for corner in np.ndindex(2, 2, 2):
        k = _pack(base + np.array(corner) * side)
        lo, hi = np.searchsorted(keys, k, "left"), np.searchsorted(keys, k, "right")
        rank = 0
        while True:
            has = np.flatnonzero(lo + rank < hi)
            if not has.size:
                break
            ia = order[lo[has] + rank]
            d = np.linalg.norm(a[ia] - b[has], axis=1)
            ok = (d <= tol) & (sig_a[ia] == sig_b[has])
            c = np.where(ok, d if cost is None else cost(ia, has), np.inf)
            better = c < best_cost[has]
            best[has[better]], best_cost[has[better]] = ia[better], c[better]
            rank += 1
    if np.any(best < 0) or np.any(np.bincount(best, minlength=len(a)) != 1):
        return None
    return best


def _same_markers(a: np.ndarray, sig: np.ndarray, b: np.ndarray, tol: float) -> bool:
    """Whether the markers ``b`` (an image of ``a``, same signatures) are ``a``'s as a set
    of unordered point triples."""
    m = _match(a.mean(axis=1), b.mean(axis=1), sig, sig, tol,
               cost=lambda ia, ib: _triple_distance(a[ia], b[ib]))
    return m is not None and bool(np.all(_triple_distance(a[m], b) <= tol))


def _triple_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """How far each unordered point triple of ``a`` is from the matching one of ``b``: the
    largest distance from a point of either to the nearest point of the other."""
    d = np.linalg.norm(a[:, :, None, :] - b[:, None, :, :], axis=-1)  # (N, 3, 3)
    return np.maximum(d.min(axis=2).max(axis=1), d.min(axis=1).max(axis=1))


def _same_surface(faces: "_Faces", vertices: np.ndarray, q: np.ndarray, tol: float) -> bool:
    """Whether a surface (its :func:`_flat_faces` and its distinct vertices) maps onto
    itself under ``q``, however it is triangulated: each flat face (coplanar neighbours of
    one signature and facing, merged) must land on a face of the same signature, area,
    centroid, second moments and front (a reflection reverses the vertex order, not the
    front), and its vertices on its vertices. A quad split along one diagonal is the
    mirror image of the same quad split along the other."""
    if not len(faces.area):
        return True
    image = faces.carried(q)
    facing = lambda ia, ib: 1.0 - np.einsum("ij,ij->i", faces.normal[ia],  # noqa: E731
                                            image.normal[ib])
    m = _match(faces.centroid, image.centroid, faces.sig, image.sig, 10 * tol, facing)
    if m is None:
        return False
    fa = faces.take(m)
    close = (np.abs(fa.area - image.area) <= 40 * tol * np.sqrt(fa.area)) & \
        (np.abs(fa.spread - image.spread).max(axis=(1, 2)) <= 10 * tol * faces.scale) & \
        (np.einsum("ij,ij->i", fa.normal, image.normal) >= 1.0 - 1e-6)
    if not np.all(close):
        return False
    none = np.zeros(len(vertices), np.int64)
    return _match(vertices, vertices @ q.T, none, none, 10 * tol) is not None


def _welded(t: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The distinct vertices (V, 3) of triangles ``t`` and each corner's index (T, 3),
    corners within the tolerance's grid being one vertex."""
    keys = _pack(np.floor(t.reshape(-1, 3) / (10 * tol) + 0.3731).astype(np.int64))
    _, first, index = np.unique(keys, return_index=True, return_inverse=True)
    return t.reshape(-1, 3)[first], index.reshape(-1, 3)


class _Faces:
    """Flat faces of a surface: signature, area (m^2), centroid (m), second moments about
    the centroid per area (3x3, m^2), unit front normal."""

    def __init__(self, sig, area, centroid, spread, normal, scale):
        self.sig, self.area, self.centroid = sig, area, centroid
        self.spread, self.normal, self.scale = spread, normal, scale

    def carried(self, q: np.ndarray) -> "_Faces":
        return _Faces(self.sig, self.area, self.centroid @ q.T,
                      np.einsum("ij,njk,lk->nil", q, self.spread, q), self.normal @ q.T,
                      self.scale)

    def take(self, i: np.ndarray) -> "_Faces":
        return _Faces(self.sig[i], self.area[i], self.centroid[i], self.spread[i],
                      self.normal[i], self.scale)


def _flat_faces(t: np.ndarray, sig: np.ndarray, tol: float) -> _Faces:
    """Triangles merged into flat faces: edge-sharing neighbours of one signature in one
    plane facing one way."""
    if not len(t):
        z = np.zeros(0)
        return _Faces(np.zeros(0, np.int64), z, z.reshape(0, 3), z.reshape(0, 3, 3),
                      z.reshape(0, 3), 1.0)
    n = _normals(t)
    twice_area = np.linalg.norm(n, axis=1)
    unit = n / np.maximum(twice_area, 1e-300)[:, None]
    offset = np.einsum("ij,ij->i", unit, t[:, 0])
    _, corner = _welded(t, tol)
    edges = np.sort(np.stack([corner[:, [0, 1]], corner[:, [1, 2]], corner[:, [2, 0]]],
                             axis=1), axis=2).reshape(-1, 2)
    owner = np.repeat(np.arange(len(t)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    e, o = edges[order], owner[order]
    same = np.all(e[1:] == e[:-1], axis=1)
    i, j = o[:-1][same], o[1:][same]
    flat = (sig[i] == sig[j]) & (np.einsum("ij,ij->i", unit[i], unit[j]) >= 1.0 - 1e-9) & \
        (np.abs(offset[i] - offset[j]) <= tol) & (twice_area[i] > 0) & (twice_area[j] > 0)
    label = _components(len(t), i[flat], j[flat])
    _, face = np.unique(label, return_inverse=True)
    k = int(face.max()) + 1
    area = 0.5 * twice_area
    centre = t.mean(axis=1)
    # the second moment of a triangle about the origin: A/12 (sum v v^T + (sum v)(sum v)^T)
    s = t.sum(axis=1)
    m2 = (area / 12.0)[:, None, None] * (np.einsum("tvi,tvj->tij", t, t) +
                                         np.einsum("ti,tj->tij", s, s))
    f_area = np.bincount(face, area, k)
    f_m1 = np.stack([np.bincount(face, area * centre[:, d], k) for d in range(3)], axis=1)
    f_m2 = np.zeros((k, 3, 3))
    np.add.at(f_m2, face, m2)
    safe = np.maximum(f_area, 1e-300)
    centroid = f_m1 / safe[:, None]
    spread = f_m2 / safe[:, None, None] - np.einsum("ni,nj->nij", centroid, centroid)
    first = np.zeros(k, np.int64)
    first[face[::-1]] = np.arange(len(t))[::-1]
    scale = float(max(np.ptp(t.reshape(-1, 3), axis=0).max(), 1e-12))
    return _Faces(sig[first], f_area, centroid, spread, unit[first], scale)


def _components(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The smallest member of each node's connected component, for ``n`` nodes joined by
    the edges ``i``-``j``: labels spread along edges and jump along their own links until
    nothing changes."""
    label = np.arange(n)
    while True:
        before = label.copy()
        low = np.minimum(label[i], label[j])
        np.minimum.at(label, i, low)
        np.minimum.at(label, j, low)
        label = label[label]
        if np.array_equal(label, before):
            return label


def _normals(t: np.ndarray) -> np.ndarray:
    """Each triangle's normal by its vertex order (front faces counter-clockwise)."""
    return np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
