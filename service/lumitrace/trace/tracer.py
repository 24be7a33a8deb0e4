"""The photon tracer: wavefront photon paths through the scene with Embree.

A batch is a pure function ``(prepared scene, emitter, seed, first photon, count) ->
BatchTally``: photon i's path depends on nothing but the scene, the seed and i, so batches
can run on any thread or machine and an edit can retrace exactly the photons it affects.
All photons of a batch advance one bounce at a time; Embree's ``run`` releases the GIL, so
two threads tracing two batches keep both cores busy.

Geometry is traced in a normalised frame (centred on the luminaire, largest half-extent 1)
so that the float32 precision Embree works in, and the ray offsets, are the same whether
the luminaire is modelled in millimetres or metres, at the origin or a kilometre away.
Directions are unchanged by that frame, so escaping photons are binned in the stage's axes.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import rng
from ..film.cubemap import texel_index
from .emission import emit
from .scattering import UNPOLARISED, MaterialTable, kind_runs, scatter
from .sampling import cross, dot
from ..scene import DIELECTRIC, Emitter, Scene

#: Ray origin offset off a surface, in normalised units (1 = the luminaire's half-size).
RAY_EPSILON = 1e-5
#: Hit points are taken this far (normalised units) before Embree's float32 hit distance.
RAY_BACKOFF = 0.5 * RAY_EPSILON
#: A hit closer to the ray's plane crossing than this (normalised units, along the normal)
#: is checked against the float64 origin: float32 rounding can put an origin that is just
#: off one face onto another one near an edge (see :func:`trace_batch`).
NEAR_HIT = 1e-6
#: Default maximum number of surface interactions; photons still alive then are cut.
MAX_DEPTH = 512


@dataclass
class PreparedScene:
    """Scene arrays in the normalised frame plus the Embree scene built from them.

    Unit triangle normals (front = counter-clockwise) and first corners are (3, T) arrays.
    """

    scene: Scene
    center: np.ndarray
    scale: float
    normals: np.ndarray
    corners: np.ndarray  # (3, T) first corner of every triangle, normalised
    material_index: np.ndarray
    triangle_kind: np.ndarray
    polarised: bool
    table: MaterialTable | None
    embree: object = field(default=None, repr=False)

    @property
    def triangle_count(self) -> int:
        return int(self.normals.shape[1])

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> dict:
        """Embree closest hits for float32 rays (N,3): ``primID`` (-1 = miss), ``tfar``."""
        if self.embree is None:
            n = origins.shape[0]
            return {"primID": np.full(n, -1, np.int32), "tfar": np.full(n, np.inf, np.float32)}
        return self.embree.run(origins, directions, output=1)


def _emitter_reach(e: Emitter) -> float:
    """Distance (local units) from the light's origin that its emitting surface reaches.

    Only the sizes of the light's own kind count: the others keep their dataclass defaults
    (1 stage unit), which would make a 1 mm LED modelled in metres a metre wide and the
    normalised frame, hence float rounding and ray offsets, depend on the stage's unit.
    """
    if e.kind == "sphere":
        return 0.0 if e.treat_as_point else e.radius  # a point light has no surface
    if e.kind == "disk":
        return e.radius
    if e.kind == "rect":
        return 0.5 * float(np.hypot(e.width, e.height))
    return float(np.hypot(0.5 * e.length, e.radius))


def _bounds(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds (world m) of the triangles and the emitters' surfaces."""
    pts = [scene.triangles.reshape(-1, 3)] if scene.triangles.size else []
    for e in scene.emitters:
        m = np.asarray(e.to_world, dtype=np.float64)
        reach = np.linalg.norm(m[:3, :3], 2) * _emitter_reach(e)
        pts.append(m[:3, 3][None, :] + reach * np.array([[-1.0, -1, -1], [1, 1, 1]]))
    allp = np.concatenate(pts, axis=0)
    return allp.min(axis=0), allp.max(axis=0)


def prepare(scene: Scene) -> PreparedScene:
    """Normalise the scene and build the Embree acceleration structure."""
    lo, hi = _bounds(scene)
    center = 0.5 * (lo + hi)
    scale = float(0.5 * (hi - lo).max())
    if not scale > 0.0:  # a lone point light: any scale will do
        scale = 1.0
    tri = (np.asarray(scene.triangles, dtype=np.float64) - center) / scale
    v0 = np.ascontiguousarray(tri[:, 0].T)
    e1 = np.ascontiguousarray(tri[:, 1].T) - v0
    e2 = np.ascontiguousarray(tri[:, 2].T) - v0
    nrm = cross(e1, e2)
    length = np.sqrt(dot(nrm, nrm))
    normals = np.divide(nrm, length, out=np.zeros_like(nrm), where=length > 0)
    embree = None
    table = None
    kind = np.zeros(tri.shape[0], np.int8)
    if tri.shape[0]:
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        embree = rtcore_scene.EmbreeScene(robust=True)
        TriangleMesh(embree, np.ascontiguousarray(tri, dtype=np.float32))
        table = MaterialTable.from_materials(scene.materials)
        kind = np.take(table.kind, np.asarray(scene.material_index))
    return PreparedScene(scene=scene, center=center, scale=scale,
                         normals=normals, corners=v0, material_index=np.asarray(scene.material_index), triangle_kind=kind,
                         polarised=bool(np.any(kind == DIELECTRIC)),
                         table=table, embree=embree)


@dataclass
class BatchTally:
    """What one batch of photons did: escapes per texel and where the rest went.

    ``counts`` is (2, texels): escapes of the photons in each of two pseudo-random halves.
    """

    emitter: int
    start: int
    photons: int
    counts: np.ndarray
    absorbed: int = 0
    cut: int = 0
    segments: int = 0
    rays: list | None = None

    @property
    def escaped(self) -> int:
        return int(self.counts.sum())


def trace_batch(ps: PreparedScene, emitter_number: int, seed: int, start: int, count: int,
                resolution: int, max_depth: int = MAX_DEPTH, record_rays: bool = False) -> BatchTally:
    """Trace photons ``start .. start+count-1`` of one emitter and tally them.

    With ``record_rays`` every traced ray (float32 origins, directions) is kept, for the
    benchmark that replays the same rays through bare Embree.
    """
    e: Emitter = ps.scene.emitters[emitter_number]
    key = rng.stream_key(seed, e.key)
    idx = np.arange(start, start + count, dtype=np.int64)
    base = rng.photon_hash(key, idx)
    p, d, n_emit = emit(e, key, idx, normals=True)
    # off the emitting surface along its normal, as off any surface: an offset along d would
    # vanish for grazing photons and start them inside a part the light lies on
    o = (p - ps.center[:, None]) / ps.scale + RAY_EPSILON * n_emit
    # polarisation matters only where a dielectric can see it; drawn at first need
    pol = np.full_like(d, UNPOLARISED) if ps.polarised else None
    ntex = 6 * resolution * resolution
    tally = BatchTally(emitter_number, start, count, np.zeros((2, ntex), np.int64),
                       rays=[] if record_rays else None)

    for depth in range(max_depth + 1):
        if base.size == 0:
            break
        o32 = np.ascontiguousarray(o.T, dtype=np.float32)
        d32 = np.ascontiguousarray(d.T, dtype=np.float32)
        if record_rays:
            tally.rays.append((o32, d32))
        hit = ps.intersect(o32, d32)
        tally.segments += base.size
        prim = hit["primID"]
        miss = prim < 0
        if miss.any():
            # escapes per texel, in two halves split by the photon hash's lowest bit: two
            # independent estimates of the same map, for the error estimate
            half = (np.compress(miss, base) & np.uint64(1)).astype(np.int64)
            texel = texel_index(np.compress(miss, d, axis=1).T, resolution)
            tally.counts += np.bincount(texel + ntex * half, minlength=2 * ntex).reshape(2, ntex)
        h = np.flatnonzero(~miss)
        if h.size == 0:
            break
        if depth == max_depth:
            tally.cut += int(h.size)
            break
        prim = np.take(prim, h)
        kind = np.take(ps.triangle_kind, prim)
        runs = kind_runs(kind)
        if len(runs) > 1:  # group the wave by scattering model: slices, not gathers
            order = np.argsort(kind, kind="stable")
            h, prim = np.take(h, order), np.take(prim, order)
            runs = kind_runs(np.take(kind, order))
        base, o, d = np.take(base, h), np.take(o, h, axis=1), np.take(d, h, axis=1)
        if pol is not None:
            pol = np.take(pol, h, axis=1)
        # Embree's float32 tfar puts the hit point up to a few ulps beyond the surface, along
        # the ray; near an edge that can be behind the adjoining face, and the normal offset
        # below does not undo it (light leaked out of closed boxes at their edges). Backing
        # up along the ray, by more than that error but never beyond the origin, keeps the
        # point in the space the ray crossed.
        t = np.take(hit["tfar"], h).astype(np.float64)
        p = o + (t - np.minimum(RAY_BACKOFF, 0.5 * t)) * d
        ng = np.take(ps.normals, prim, axis=1)
        # A hit at about the ray's origin, on a face the float64 origin lies in front of
        # while the ray moves away from it, is no hit: the origin was just off this face
        # (an edge or corner away from the face it left) and float32 rounding put it on
        # it. The photon goes on unchanged (escaped out of a corner of a closed box
        # otherwise). Only hits within float32 rounding of the origin need the test.
        cos_in = dot(d, ng)
        near = np.flatnonzero(t * np.abs(cos_in) < NEAR_HIT)
        stay = None
        if near.size:
            rel = np.take(o, near, axis=1) - np.take(ps.corners, np.take(prim, near), axis=1)
            away = dot(rel, np.take(ng, near, axis=1)) * np.take(cos_in, near) > 0.0
            if away.any():
                stay = near[away]
        rnd = rng.uniforms_from(base, (depth + 1) * rng.DIMS_PER_BOUNCE, 4)
        d_in, pol_in = d, pol
        d, alive, pol = scatter(ps.table, np.take(ps.material_index, prim), d, ng, rnd, pol, runs)
        if stay is not None:
            d[:, stay] = d_in[:, stay]
            alive[stay] = True
            if pol is not None:
                pol[:, stay] = pol_in[:, stay]
        n_alive = int(np.count_nonzero(alive))
        tally.absorbed += int(base.size - n_alive)
        if n_alive < base.size:
            base = np.compress(alive, base)
            d, p, ng = (np.compress(alive, a, axis=1) for a in (d, p, ng))
            if pol is not None:
                pol = np.compress(alive, pol, axis=1)
        o = p + (RAY_EPSILON * np.sign(dot(d, ng))) * ng
    return tally
