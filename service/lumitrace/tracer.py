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
from .cubemap import texel_index
from .emission import emit
from .materials import MaterialTable, random_polarisation, scatter
from .scene import Emitter, Scene

#: Ray origin offset off a surface, in normalised units (1 = the luminaire's half-size).
RAY_EPSILON = 1e-5
#: Default maximum number of surface interactions; photons still alive then are cut.
MAX_DEPTH = 512


@dataclass
class PreparedScene:
    """Scene arrays in the normalised frame plus the Embree scene built from them."""

    scene: Scene
    center: np.ndarray
    scale: float
    v0: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    normals: np.ndarray
    material_index: np.ndarray
    table: MaterialTable | None
    embree: object = field(default=None, repr=False)

    @property
    def triangle_count(self) -> int:
        return int(self.v0.shape[0])

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> dict:
        """Embree closest hits for float32 rays (N,3): ``primID`` (-1 = miss), ``u``, ``v``."""
        if self.embree is None:
            n = origins.shape[0]
            return {"primID": np.full(n, -1, np.int32), "u": np.zeros(n, np.float32),
                    "v": np.zeros(n, np.float32)}
        return self.embree.run(origins, directions, output=1)


def _bounds(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds (world m) of the triangles and the emitters' origins."""
    pts = [scene.triangles.reshape(-1, 3)] if scene.triangles.size else []
    for e in scene.emitters:
        m = np.asarray(e.to_world, dtype=np.float64)
        reach = np.linalg.norm(m[:3, :3], axis=0).max() * max(e.radius, e.width, e.height, e.length)
        pts.append(m[:3, 3][None, :] + reach * np.array([[-1.0, -1, -1], [1, 1, 1]]))
    allp = np.concatenate(pts, axis=0)
    return allp.min(axis=0), allp.max(axis=0)


def prepare(scene: Scene) -> PreparedScene:
    """Normalise the scene and build the Embree acceleration structure."""
    lo, hi = _bounds(scene)
    center = 0.5 * (lo + hi)
    scale = float(max(0.5 * (hi - lo).max(), 1e-12))
    tri = (np.asarray(scene.triangles, dtype=np.float64) - center) / scale
    v0 = tri[:, 0]
    e1 = tri[:, 1] - v0
    e2 = tri[:, 2] - v0
    nrm = np.cross(e1, e2)
    length = np.linalg.norm(nrm, axis=1, keepdims=True)
    normals = np.divide(nrm, length, out=np.zeros_like(nrm), where=length > 0)
    embree = None
    table = None
    if tri.shape[0]:
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        embree = rtcore_scene.EmbreeScene(robust=True)
        TriangleMesh(embree, np.ascontiguousarray(tri, dtype=np.float32))
        table = MaterialTable.from_materials(scene.materials)
    return PreparedScene(scene=scene, center=center, scale=scale, v0=v0, e1=e1, e2=e2,
                         normals=normals, material_index=np.asarray(scene.material_index),
                         table=table, embree=embree)


@dataclass
class BatchTally:
    """What one batch of photons did: escapes per texel and where the rest went."""

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
    p, d = emit(e, key, idx)
    pol = random_polarisation(d, rng.uniforms(key, idx, rng.EMISSION_POLARISATION, 1)[0])
    o = (p - ps.center) / ps.scale + RAY_EPSILON * d
    ntex = 6 * resolution * resolution
    tally = BatchTally(emitter_number, start, count, np.zeros(ntex, np.int64),
                       rays=[] if record_rays else None)

    for depth in range(max_depth + 1):
        if idx.size == 0:
            break
        o32 = o.astype(np.float32)
        d32 = d.astype(np.float32)
        if record_rays:
            tally.rays.append((o32, d32))
        hit = ps.intersect(o32, d32)
        tally.segments += idx.size
        prim = hit["primID"]
        miss = prim < 0
        if miss.any():
            tally.counts += np.bincount(texel_index(d[miss], resolution), minlength=ntex)
        h = np.nonzero(~miss)[0]
        if h.size == 0:
            idx = idx[:0]
            break
        if depth == max_depth:
            tally.cut += int(h.size)
            break
        prim = prim[h]
        idx, d, pol = idx[h], d[h], pol[h]
        u = hit["u"][h].astype(np.float64)[:, None]
        v = hit["v"][h].astype(np.float64)[:, None]
        p = ps.v0[prim] + u * ps.e1[prim] + v * ps.e2[prim]
        ng = ps.normals[prim]
        rnd = rng.uniforms(key, idx, (depth + 1) * rng.DIMS_PER_BOUNCE, 4)
        d, alive, pol = scatter(ps.table, ps.material_index[prim], d, ng, rnd, pol)
        tally.absorbed += int(idx.size - np.count_nonzero(alive))
        keep = np.nonzero(alive)[0]
        idx, d, p, ng, pol = idx[keep], d[keep], p[keep], ng[keep], pol[keep]
        side = np.sign(np.einsum("ij,ij->i", d, ng))
        o = p + (RAY_EPSILON * side)[:, None] * ng
    return tally
