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
from functools import cached_property

import numpy as np

from ..errors import LumitraceError
from ..scene import DIELECTRIC, Scene, point_bounds
from ..film import goniometer as gonio
from ..film.goniometer import Goniometer
from .vectors import cross, dot
from . import embree as _embree
from .embree import PartScene, library
from .emission import emission_args
from .records import CellGrid, _axis_masks, part_bits
from .scattering import MaterialTable

#: :attr:`PreparedScene.hit_args` of a scene without geometry: no Embree call, no box.
NO_HITS = (np.uint64(0), np.uint64(0), np.zeros(0, np.int64), np.zeros(0, np.int64),
           np.zeros(3), np.zeros(3))


#: Margin (normalised units) around the triangles' bounds within which rays go to Embree.
REACH_MARGIN = 1e-3


@dataclass(frozen=True)
class TracingFrame:
    """The normalised tracing frame: ``p_traced = (p_world - center) / scale`` (world m),
    and the grid of the photons' cell masks over the luminaire (pinned with it)."""

    center: tuple[float, float, float]
    scale: float
    grid: CellGrid = CellGrid()
    goniometer: Goniometer | None = None  # None: the scene's own, at prepare

    @classmethod
    def of(cls, scene: Scene) -> "TracingFrame":
        """The frame centred on ``scene``'s bounds, largest half-extent 1."""
        lo, hi = point_bounds(scene.bound_points())
        center = 0.5 * (lo + hi)
        scale = float(0.5 * (hi - lo).max())
        if not scale > 0.0:  # a lone point light: any scale will do
            scale = 1.0
        return cls(tuple(float(c) for c in center), scale,
                   CellGrid.around((lo - center) / scale, (hi - center) / scale),
                   Goniometer.of(scene))

    def check_fits(self, scene: Scene) -> None:
        """Raise unless ``scene`` traces accurately in this frame: its bounds within
        :data:`FRAME_REACH` frame units of the centre and, for a scene with extent, at
        least 1 / FRAME_REACH of a unit across (float32 geometry and the ray offsets are
        sized for a unit box)."""
        own = TracingFrame.of(scene)
        offset = float(np.max(np.abs(np.subtract(own.center, self.center)))) / self.scale
        size = own.scale / self.scale
        pts = scene.bound_points()
        has_extent = bool(np.ptp(pts, axis=0).max() > 0) if len(pts) else False
        if not (np.isfinite(offset) and offset + size <= FRAME_REACH) or \
                (has_extent and not size >= 1.0 / FRAME_REACH):
            raise LumitraceError(
                f"the tracing frame (centre {', '.join(f'{c:g}' for c in self.center)} m, "
                f"scale {self.scale:g} m) does not fit the luminaire (centre "
                f"{', '.join(f'{c:.6g}' for c in own.center)} m, half extent "
                f"{own.scale:.6g} m): its parts would lie {offset + size:.3g} frame units "
                f"out, at {size:.3g} units across; give the frame the service reports "
                "for this luminaire", "--frame")


#: How far (in frame units, the frame's scale) a pinned frame may place the luminaire's
#: bounds from its centre, and the inverse of the smallest size it may shrink it to.
FRAME_REACH = 1.0e3


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
    goniometer: Goniometer | None = None

    @property
    def frame(self) -> TracingFrame:
        return TracingFrame(tuple(float(c) for c in self.center), self.scale, self.grid,
                            self.goniometer)

    @property
    def triangle_count(self) -> int:
        return int(self.normals.shape[1])

    @cached_property
    def spectral(self) -> bool:
        """Whether photons carry wavelengths: some surface has a colour or dispersion (read
        once: the scene's answer looks at every emitter, and every batch asks)."""
        return self.scene.colour == "spectral"

    @cached_property
    def kernel_args(self) -> tuple:
        """The scene's arrays as :func:`~lumitrace.trace.kernels.bounce` takes them:
        normals and first corners (T, 3), material and part of every triangle, then the
        material table (kind, reflectance, specular, transmittance, ior, alpha), the
        polarisation flag, the spectral flag, the spectral tables (M, bands), which
        materials disperse and which are neutral (M,) (1-element stand-ins when the scene
        is not spectral)."""
        t = self.table or MaterialTable.from_materials(self.scene.materials)
        spectral = self.spectral
        if spectral and t.spectra is None:
            t = MaterialTable.from_materials(self.scene.materials, spectral=True)
        if spectral:
            colour = tuple(np.ascontiguousarray(a, np.float64) for a in t.spectra) + (
                np.array([m.dispersive for m in self.scene.materials], np.bool_),
                np.array([m.neutral for m in self.scene.materials], np.bool_))
        else:
            colour = (np.zeros((1, 1)),) * 4 + (np.zeros(1, np.bool_),) * 2
        f64 = lambda a: np.ascontiguousarray(a, np.float64)  # noqa: E731
        part = (self.part_index if self.part_index is not None and self.part_index.size
                else np.zeros(self.triangle_count, np.int64))
        return (f64(self.normals.T), f64(self.corners.T),
                np.ascontiguousarray(self.material_index, np.int64),
                np.ascontiguousarray(part, np.int64), np.ascontiguousarray(t.kind, np.int64),
                f64(t.reflectance), f64(t.specular), f64(t.transmittance), f64(t.ior),
                f64(t.alpha), bool(self.polarised), spectral) + colour

    @cached_property
    def band_weights(self) -> list[np.ndarray]:
        """Per emitter, X, Y, Z per band of a photon of unit throughput, (3, bands) (D65
        for a light without a spectrum); stand-ins when the scene is not spectral."""
        if not self.spectral:
            return [np.zeros((3, 1))] * len(self.scene.emitters)
        from ..scene.spectra import band_weights, d65

        return [band_weights(e.spectrum if e.spectrum else d65())
                for e in self.scene.emitters]

    @cached_property
    def emitter_args(self) -> list[tuple]:
        """Every emitter as the emission kernel takes it (tables, transforms), made once."""
        return [emission_args(e) for e in self.scene.emitters]

    @cached_property
    def reach_box(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounds (normalised) of the triangles, widened well beyond float32 rounding:
        a ray that misses this box meets no triangle."""
        # the world bounds normalised are the normalised triangles' bounds, to the bit
        lo, hi = ((b - self.center) / self.scale
                  for b in point_bounds(np.asarray(self.scene.triangles, np.float64)))
        margin = REACH_MARGIN * max(1.0, float(np.abs(lo).max()), float(np.abs(hi).max()))
        return lo - margin, hi + margin

    @cached_property
    def gonio_args(self) -> tuple:
        """The tracing frame and the goniophotometer as the kernel takes them."""
        g = self.goniometer
        f64 = lambda a: np.ascontiguousarray(a, np.float64)  # noqa: E731
        return (f64(self.center), float(self.scale), f64(g.axes), f64(g.lo), f64(g.hi),
                f64(gonio.EXTRA_EDGES), gonio.C_STEP,
                gonio.GAMMA_STEP, gonio.N_C, gonio.N_GAMMA, gonio.EXIT_SIDE, gonio.N_BINS)

    @cached_property
    def grid_args(self) -> tuple:
        """Each triangle's part bit and the record grid (bounds, cells per axis, per-axis
        cell masks), for the photons' records."""
        bits = (self.part_bits if self.part_bits is not None and self.part_bits.size
                else np.zeros(self.triangle_count, np.uint64))
        g = self.grid
        return (np.ascontiguousarray(bits, np.uint64), np.asarray(g.lo, np.float64),
                np.asarray(g.hi, np.float64), np.asarray(g.n, np.int64),
                *(np.ascontiguousarray(m) for m in _axis_masks(tuple(g.n))))

    @property
    def hit_args(self) -> tuple | None:
        """Embree as a deep :func:`~lumitrace.trace.kernels.bounce` calls it, and the box
        a ray must meet to be cast (no geometry: nothing to call), or None where only
        embreex's batches serve."""
        if self.embree is None:
            return NO_HITS
        if isinstance(self.embree, PartScene):
            return (*self.embree.hit_args, *self.reach_box)
        return None

    def intersect(self, origins: np.ndarray, directions: np.ndarray,
                  prim: np.ndarray | None = None, tfar: np.ndarray | None = None) -> dict:
        """Embree closest hits for float32 rays (N,3): ``primID`` (-1 = miss), ``tfar``
        (written into ``prim`` and ``tfar`` when given and the scene is a PartScene)."""
        if self.embree is None:
            n = origins.shape[0]
            return {"primID": np.full(n, -1, np.int32), "tfar": np.full(n, np.inf, np.float32)}
        if isinstance(self.embree, PartScene):
            return self.embree.run(origins, directions, prim, tfar)
        return self.embree.run(origins, directions, output=1)


def normalised(scene: Scene, center: np.ndarray, scale: float) -> np.ndarray:
    """The scene's triangles (T, 3, 3) in the tracing frame (float64; Embree takes them
    rounded to float32)."""
    return (np.asarray(scene.triangles, dtype=np.float64) - center) / scale


def embree_scene(triangles: np.ndarray, part_index, parts: bool = True,
                 frames: list | None = None):
    """The Embree scene of float32 triangles (T, 3, 3): one geometry per part through
    Embree's C API (:class:`~lumitrace.trace.embree.PartScene`, the parts' ``frames`` as
    :func:`part_frames` makes them) where its library is found and ``parts``, else
    embreex's one geometry. Both give the same hits."""
    if parts and library() is not None:
        return PartScene(triangles, part_index, frames=frames)
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    embree = rtcore_scene.EmbreeScene(robust=True)
    TriangleMesh(embree, triangles)
    return embree


#: A part's frame stands for its triangles where it puts these many of them, spread over
#: the part, within this share of the scene's size of where the scene has them: a part
#: whose triangles were moved or replaced, its frame not, is traced from its triangles.
FRAME_SAMPLE = 256
FRAME_TOLERANCE = 1e-9


def part_frames(scene: Scene, center: np.ndarray, scale: float) -> list | None:
    """Per part, None or (its own triangles (t, 3, 3) float32, the transform (12,) float32,
    columns of 3 x 4, from them to the tracing frame) where the scene is large enough to be
    two-level and the part's frame places its triangles, one run of them, where the scene
    has them (checked on :data:`FRAME_SAMPLE` of them)."""
    if not scene.part_frames or len(scene.triangles) < _embree.TWO_LEVEL_TRIANGLES:
        return None
    parts = np.asarray(scene.part_index)
    tri = np.asarray(scene.triangles)
    cut = np.flatnonzero(parts[1:] != parts[:-1]) + 1
    runs: dict[int, tuple | None] = {}  # each part's one run of triangles
    for a, b in zip(np.r_[0, cut].tolist(), np.r_[cut, len(parts)].tolist()):
        g = int(parts[a])
        runs[g] = None if g in runs else (a, b)
    size = FRAME_TOLERANCE * max(float(np.abs(tri[::max(1, len(tri) // 4096)]).max()), 1e-12)
    out = []
    for g, f in enumerate(scene.part_frames):
        run = runs.get(g)
        if f is None or run is None or run[1] - run[0] != len(f.local):
            out.append(None)
            continue
        n = len(f.local)
        pick = np.unique(np.linspace(0, n - 1, min(n, FRAME_SAMPLE)).astype(np.int64))
        placed = f.local[pick].astype(np.float64) @ f.linear + f.offset
        if not np.allclose(placed, tri[run[0] + pick], rtol=0.0, atol=size):
            out.append(None)
            continue
        m = np.asarray(f.linear, np.float64) / scale  # row i: where own axis i goes
        t = (np.asarray(f.offset, np.float64) - center) / scale
        out.append((f.local, np.concatenate([m[0], m[1], m[2], t]).astype(np.float32)))
    return out


def prepare(scene: Scene, frame: TracingFrame | None = None,
            previous: PreparedScene | None = None) -> PreparedScene:
    """Normalise the scene (in ``frame``, else its own) and build the Embree structure.

    With ``previous`` (the same luminaire in the same frame before an edit, no longer
    traced) its Embree scene is updated in place where it can be: only the parts whose
    triangles changed are rebuilt (see :meth:`~lumitrace.trace.embree.PartScene.update`).
    """
    frame = frame or TracingFrame.of(scene)
    center = np.array(frame.center, dtype=np.float64)
    scale = float(frame.scale)
    tri = normalised(scene, center, scale)
    v0 = np.ascontiguousarray(tri[:, 0].T)
    e1 = np.ascontiguousarray(tri[:, 1].T) - v0
    e2 = np.ascontiguousarray(tri[:, 2].T) - v0
    nrm = cross(e1, e2)
    length = np.sqrt(dot(nrm, nrm))
    with np.errstate(divide="ignore", invalid="ignore"):
        normals = nrm / length  # (in place of a zeroed array: page faults of 24 MB at 1M)
    normals[:, ~(length > 0)] = 0.0
    embree = None
    table = None
    kind = np.zeros(tri.shape[0], np.int8)
    if tri.shape[0]:
        tri32 = np.ascontiguousarray(tri, dtype=np.float32)
        embree = previous.embree if previous is not None else None
        frames = part_frames(scene, center, scale)
        if not (isinstance(embree, PartScene) and previous.center.tolist() == center.tolist()
                and previous.scale == scale and embree.update(tri32, scene.part_index,
                                                              frames)):
            embree = embree_scene(tri32, scene.part_index, frames=frames)
        table = MaterialTable.from_materials(scene.materials,
                                             spectral=scene.colour == "spectral")
        kind = np.take(table.kind, np.asarray(scene.material_index))
    return PreparedScene(scene=scene, center=center, scale=scale,
                         normals=normals, corners=v0,
                         material_index=np.asarray(scene.material_index), triangle_kind=kind,
                         polarised=bool(np.any(kind == DIELECTRIC)),
                         table=table, embree=embree, grid=frame.grid,
                         goniometer=frame.goniometer or Goniometer.of(scene),
                         part_index=np.asarray(scene.part_index, np.int64),
                         part_bits=np.take(part_bits(scene.parts), scene.part_index)
                         if len(scene.parts) and tri.shape[0] else np.zeros(0, np.uint64))
