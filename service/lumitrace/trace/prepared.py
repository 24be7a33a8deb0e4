"""The scene made ready to trace: a normalised frame, float32 geometry and its Embree scene.

Geometry is traced in a normalised frame (centred on the luminaire, largest half-extent 1)
so that the float32 precision Embree works in, and the ray offsets, are the same whether
the luminaire is modelled in millimetres or metres, at the origin or a kilometre away.
Directions are unchanged by that frame, so escaping photons are binned in the stage's axes.
A session can pin the frame (:class:`TracingFrame`), so that an edit which changes the
luminaire's bounds does not move every unchanged part's float32 coordinates.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..scene import DIELECTRIC, Emitter, Scene
from .sampling import cross, dot
from .records import CellGrid, part_bits
from .scattering import MaterialTable


@dataclass(frozen=True)
class TracingFrame:
    """The normalised tracing frame: ``p_traced = (p_world - center) / scale`` (world m),
    and the grid of the photons' cell masks over the luminaire (pinned with it)."""

    center: tuple[float, float, float]
    scale: float
    grid: CellGrid = CellGrid()

    @classmethod
    def of(cls, scene: Scene) -> "TracingFrame":
        """The frame centred on ``scene``'s bounds, largest half-extent 1."""
        lo, hi = _bounds(scene)
        center = 0.5 * (lo + hi)
        scale = float(0.5 * (hi - lo).max())
        if not scale > 0.0:  # a lone point light: any scale will do
            scale = 1.0
        return cls(tuple(float(c) for c in center), scale,
                   CellGrid.around((lo - center) / scale, (hi - center) / scale))


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
    part_bits: np.ndarray = field(default=None, repr=False)  # (T,) uint64, see records
    grid: CellGrid = CellGrid()
    part_index: np.ndarray = field(default=None, repr=False)  # (T,) part of each triangle

    @property
    def frame(self) -> TracingFrame:
        return TracingFrame(tuple(float(c) for c in self.center), self.scale, self.grid)

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


def prepare(scene: Scene, frame: TracingFrame | None = None) -> PreparedScene:
    """Normalise the scene (in ``frame``, else its own) and build the Embree structure."""
    frame = frame or TracingFrame.of(scene)
    center = np.array(frame.center, dtype=np.float64)
    scale = float(frame.scale)
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
                         normals=normals, corners=v0,
                         material_index=np.asarray(scene.material_index), triangle_kind=kind,
                         polarised=bool(np.any(kind == DIELECTRIC)),
                         table=table, embree=embree, grid=frame.grid,
                         part_index=np.asarray(scene.part_index, np.int64),
                         part_bits=np.take(part_bits(scene.parts), scene.part_index)
                         if len(scene.parts) and tri.shape[0] else np.zeros(0, np.uint64))
