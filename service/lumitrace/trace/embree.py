"""Embree 4 through its C API, from the library the embreex wheel ships: one geometry per
part, intersected by a compiled kernel, and the geometries of edited parts rebuilt in place.

A large scene (:data:`TWO_LEVEL_TRIANGLES` or more) is two-level: each part its own Embree
scene, placed in the top scene by an instance, so an edit rebuilds the edited parts' own
structures and a top level over the parts, not every triangle. A part with a frame of its
own (:class:`~lumitrace.scene.PartFrame`: one placement, as the stage reader gives) is
built from its own triangles and placed by its transform, so moving it changes that
transform alone: no triangle is rebuilt. Rays then meet it in its own space, which changes
the last bits of their distances against a one-level scene (and a grazing ray's hit, about
one in 10^4), but a fresh build of the same frames is the same structure: a fresh trace
and an incremental one meet the same triangles at the same distances. A part without one
is placed by the identity, which leaves the ray's numbers as they are.

A part's triangles go to Embree as quads (:func:`quads`): two triangles that follow one
another and share an edge (as a polygon's fan gives them) are one quad, which Embree
intersects as those same two triangles, a triangle without a partner a quad whose last
corner is repeated. Half as many primitives make a shallower tree: a ray costs 15% less
on the cups, hits the same triangles as a triangle mesh would, and its float32 distance
differs from a triangle mesh's in the last bits for a few rays in a hundred (the corners
are taken in another order).

embreex builds one geometry of all triangles, rebuilt whole after any edit, and returns six
freshly allocated arrays per call. Here each part is its own geometry, so an edit detaches
and attaches only the edited parts', the scene is committed once, and hits are written
into the tracer's own buffers. The scene has embreex's robust flag, and hits are the same
triangles as embreex's (tested). Without the library (another wheel layout, or
``LUMITRACE_EMBREE=embreex``) the tracer uses embreex: the same photons but for the rare
one whose path a distance's last bit turns.
"""
from __future__ import annotations

import ctypes
import functools
import glob
import os
import threading
from typing import NamedTuple

import numpy as np

#: Embree 4 enum values (rtcore_common.h, rtcore_buffer.h, rtcore_scene.h).
_QUAD, _INDEX, _VERTEX, _UINT4, _FLOAT3, _ROBUST = 1, 0, 1, 0x5004, 0x9003, 1 << 2
_INSTANCE, _FLOAT3X4_COLUMNS = 121, 0x9234
#: Triangles from which a scene is built two-level (a part's edit then rebuilds that part
#: alone; below it a rebuild of all is quick, and one level traces a little faster).
TWO_LEVEL_TRIANGLES = 200_000
_IDENTITY = np.array([1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0], np.float32)  # 3 x 4, columns
_P = ctypes.c_size_t  # pointers, passed as addresses
_API = {"rtcNewDevice": (_P, [ctypes.c_char_p]), "rtcNewScene": (_P, [_P]),
        "rtcSetSceneFlags": (None, [_P, ctypes.c_int]),
        "rtcNewGeometry": (_P, [_P, ctypes.c_int]),
        "rtcSetSharedGeometryBuffer": (None, [_P, ctypes.c_int, ctypes.c_uint, ctypes.c_int,
                                              _P, _P, _P, _P]),
        "rtcCommitGeometry": (None, [_P]), "rtcReleaseGeometry": (None, [_P]),
        "rtcAttachGeometryByID": (None, [_P, _P, ctypes.c_uint]),
        "rtcDetachGeometry": (None, [_P, ctypes.c_uint]), "rtcCommitScene": (None, [_P]),
        "rtcReleaseScene": (None, [_P]), "rtcGetDeviceError": (ctypes.c_int, [_P]),
        "rtcIntersect4": (None, [_P, _P, _P, _P]),
        "rtcSetGeometryInstancedScene": (None, [_P, _P]),
        "rtcSetGeometryTransform": (None, [_P, ctypes.c_uint, ctypes.c_int, _P])}
_lock = threading.Lock()


@functools.lru_cache(maxsize=1)
def library() -> ctypes.CDLL | None:
    """Embree 4's shared library as the embreex wheel ships it, its API declared; None
    when it is not found or not wanted."""
    if os.environ.get("LUMITRACE_EMBREE", "").lower() == "embreex":
        return None
    try:
        import embreex
    except ImportError:
        return None
    here = os.path.dirname(embreex.__file__)
    names = (glob.glob(os.path.join(here, os.pardir, "embreex.libs", "libembree4*"))
             + glob.glob(os.path.join(here, ".dylibs", "libembree4*"))
             + glob.glob(os.path.join(here, "*embree4*.dll")))
    for name in names:
        try:
            lib = ctypes.CDLL(name)
            for fn, (res, args) in _API.items():
                getattr(lib, fn).restype, getattr(lib, fn).argtypes = res, args
            return lib
        except (OSError, AttributeError):
            continue
    return None


def quads(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (t, 3, 3) as Embree quads: the corners (q, 4, 3) float32 and the two
    triangles each quad holds (q, 2), as :func:`~lumitrace.trace.kernels.pair_quads`
    pairs them (two that follow one another and share an edge are one quad)."""
    from .compiled import pair_quads

    tri = np.ascontiguousarray(tri, np.float32)
    return pair_quads(tri.view(np.uint32), tri)


class _Part(NamedTuple):
    """A part's geometry as Embree holds it: the shared buffers it reads (kept alive),
    whether the part is placed by a frame of its own, the triangles (t, 3, 3) float32 it was
    made of (an update compares the new ones) and each quad's two triangles (q, 2)."""

    vertices: np.ndarray
    index: np.ndarray
    framed: bool
    triangles: np.ndarray
    held: np.ndarray


def _parts(part_index, n: int) -> np.ndarray:
    """The part of each of ``n`` triangles (all part 0 when none is given)."""
    return np.asarray(part_index, np.int64) if len(part_index) else np.zeros(n, np.int64)


_devices: list[int] = []


def _device() -> int:
    """The process's one Embree device, made by the first caller: threads tracing their
    first scenes at once must not make one each (a geometry of one device in a scene of
    another mixes the scenes' hits)."""
    if not _devices:
        with _lock:
            if not _devices:
                _devices.append(library().rtcNewDevice(None))
    return _devices[0]


class PartScene:
    """The triangles (T, 3, 3) float32 of a prepared scene as an Embree scene with one
    geometry per part (``part_index`` (T,)), hits numbered as the triangles are."""

    def __init__(self, triangles: np.ndarray, part_index: np.ndarray,
                 two_level: bool | None = None, frames: list | None = None):
        """``two_level``: each part its own scene (default: from
        :data:`TWO_LEVEL_TRIANGLES` triangles on); ``frames``: per part, None or its own
        triangles (t, 3, 3) float32 and the transform (12,) float32, columns of 3 x 4, that
        places them among ``triangles`` (two-level only)."""
        from .compiled import intersect

        self.two_level = len(triangles) >= TWO_LEVEL_TRIANGLES if two_level is None \
            else bool(two_level)
        self._scenes: dict[int, int] = {}  # two-level: each part's own Embree scene

        self._lib, self._intersect = library(), intersect
        self._fn = ctypes.cast(self._lib.rtcIntersect4, ctypes.c_void_p).value
        self._part = part = _parts(part_index, len(triangles))
        self.order = np.argsort(part, kind="stable").astype(np.int64)
        self._in_order = bool(np.all(self.order == np.arange(len(part))))
        n_parts = int(part.max()) + 1 if len(part) else 0
        self.offsets = np.searchsorted(part[self.order], np.arange(n_parts)).astype(np.int64)
        self._buffers: dict[int, _Part] = {}  # each part's geometry
        self._placed: dict[int, np.ndarray] = {}  # two-level: the transforms of framed parts
        self.scene = self._lib.rtcNewScene(_device())
        self._lib.rtcSetSceneFlags(self.scene, _ROBUST)
        frames = self._frames(frames)
        for g, tri in self._by_part(triangles):
            self._attach(g, tri, frames[g])
        self._commit()
        self.rebuilt = sorted(self._buffers)  # the parts the last build or update built
        self.moved: list[int] = []  # the parts the last update placed anew, unbuilt

    def _frames(self, frames: list | None) -> list:
        """Every part's frame, None where it has none or the scene is one-level."""
        n = len(self.offsets)
        if not self.two_level or not frames:
            return [None] * n
        return [frames[g] if g < len(frames) else None for g in range(n)]

    def _by_part(self, triangles: np.ndarray):
        """(part, its float32 triangles (t, 3, 3)) for every part that has triangles."""
        tri = np.asarray(triangles, np.float32)
        if not self._in_order:  # parts laid out one after another need no copy
            tri = tri[self.order]
        bounds = np.append(self.offsets, len(tri))
        return [(g, tri[bounds[g]:bounds[g + 1]]) for g in range(len(self.offsets))
                if bounds[g + 1] > bounds[g]]

    def _attach(self, g: int, tri: np.ndarray, frame=None) -> None:
        """Attach part ``g``'s triangles (t, 3, 3) as geometry ``g`` (two-level: as the
        instance ``g`` of a scene of its own; with a ``frame``, its own triangles placed by
        its transform)."""
        lib = self._lib
        if frame is not None:
            tri = frame[0]
        tri = np.array(tri, np.float32)  # a copy: an update compares the part's new ones
        corners, held = quads(tri)
        v = np.zeros((4 * len(corners) + 1, 4), np.float32)  # 16-byte rows, one spare
        v[:-1, :3] = corners.reshape(-1, 3)
        idx = np.arange(4 * len(corners), dtype=np.uint32).reshape(-1, 4)
        geom = lib.rtcNewGeometry(_device(), _QUAD)
        lib.rtcSetSharedGeometryBuffer(geom, _VERTEX, 0, _FLOAT3, v.ctypes.data, 0, 16,
                                       len(v) - 1)
        lib.rtcSetSharedGeometryBuffer(geom, _INDEX, 0, _UINT4, idx.ctypes.data, 0, 16,
                                       len(idx))
        lib.rtcCommitGeometry(geom)
        if self.two_level:
            part = lib.rtcNewScene(_device())
            lib.rtcSetSceneFlags(part, _ROBUST)
            lib.rtcAttachGeometryByID(part, geom, 0)
            lib.rtcReleaseGeometry(geom)  # the part's scene holds it
            with _lock:
                lib.rtcCommitScene(part)
            old = self._scenes.pop(g, None)
            if old is not None:
                lib.rtcReleaseScene(old)
            self._scenes[g] = part
            self._place(g, _IDENTITY if frame is None else frame[1])
        else:
            lib.rtcAttachGeometryByID(self.scene, geom, g)
            lib.rtcReleaseGeometry(geom)  # the scene holds it
        self._buffers[g] = _Part(v, idx, frame is not None, tri, held)

    def _place(self, g: int, transform: np.ndarray) -> None:
        """Place part ``g``'s own scene in the top scene by ``transform`` (12,) float32,
        columns of 3 x 4: an instance, new or in place of the one before."""
        lib = self._lib
        if g in self._placed:
            lib.rtcDetachGeometry(self.scene, g)
        t = np.ascontiguousarray(transform, np.float32)
        geom = lib.rtcNewGeometry(_device(), _INSTANCE)
        lib.rtcSetGeometryInstancedScene(geom, self._scenes[g])
        lib.rtcSetGeometryTransform(geom, 0, _FLOAT3X4_COLUMNS, t.ctypes.data)
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometryByID(self.scene, geom, g)
        lib.rtcReleaseGeometry(geom)  # the scene holds it
        self._placed[g] = t

    def _commit(self) -> None:
        # each quad's two triangles in the scene's numbering, the parts' quads one after
        # another: part g's quad j holds triangles order[2 (quad_offsets[g] + j) + 0, 1]
        size = np.zeros(len(self.offsets), np.int64)
        for g, part in self._buffers.items():
            size[g] = len(part.held)
        self.quad_offsets = np.concatenate([[0], np.cumsum(size)[:-1]]).astype(np.int64)
        held = [self.offsets[g] + self._buffers[g].held for g in sorted(self._buffers)]
        self.quad_triangles = self.order[np.concatenate(held).reshape(-1)] if held \
            else np.zeros(0, np.int64)
        with _lock:
            self._lib.rtcCommitScene(self.scene)
            err = self._lib.rtcGetDeviceError(_device())
        if err:
            raise RuntimeError(f"Embree error {err} while building the scene")

    def update(self, triangles: np.ndarray, part_index, frames: list | None = None) -> bool:
        """Take the scene's new triangles (T, 3, 3) float32 (and parts' ``frames``, as the
        constructor takes them) where the parts are laid out as before (the same part of
        every triangle): place anew the framed parts whose own triangles are the same and
        whose transform changed, rebuild the parts whose triangles changed, commit once,
        and say True; False (nothing done) when the layout differs."""
        if not np.array_equal(_parts(part_index, len(triangles)), self._part):
            return False
        frames = self._frames(frames)
        changed, moved = [], []
        for g, tri in self._by_part(triangles):
            part = self._buffers[g]
            frame = frames[g]
            own = tri if frame is None else frame[0]
            if part.framed != (frame is not None) or not np.array_equal(part.triangles, own):
                changed.append((g, tri, frame))
            elif frame is not None and not np.array_equal(self._placed[g], frame[1]):
                moved.append((g, frame[1]))
        for g, tri, frame in changed:
            if g in self._placed:
                self._lib.rtcDetachGeometry(self.scene, g)
                del self._placed[g]
            elif not self.two_level:
                self._lib.rtcDetachGeometry(self.scene, g)
            self._attach(g, tri, frame)
        for g, transform in moved:
            self._place(g, transform)
        if changed or moved:
            self._commit()
        self.rebuilt = [g for g, _, _ in changed]
        self.moved = [g for g, _ in moved]
        return True

    @property
    def hit_args(self) -> tuple:
        """``rtcIntersect4``'s address, the scene's, and the quads' layout (each part's
        first quad, each quad's two triangles), as
        :func:`~lumitrace.trace.kernels.intersect` and a deep bounce take them."""
        return np.uint64(self._fn), np.uint64(self.scene), self.quad_offsets, \
            self.quad_triangles

    def run(self, origins: np.ndarray, directions: np.ndarray, prim: np.ndarray | None = None,
            tfar: np.ndarray | None = None) -> dict:
        """Closest hits of float32 rays (N, 3): ``primID`` (int32, -1 = none) and ``tfar``
        (float32, inf = none), into ``prim`` and ``tfar`` when given."""
        n = len(origins)
        prim = np.empty(n, np.int32) if prim is None else prim[:n]
        tfar = np.empty(n, np.float32) if tfar is None else tfar[:n]
        fn, scene, offsets, order = self.hit_args
        self._intersect(fn, scene, origins, directions, offsets, order, prim, tfar)
        return {"primID": prim, "tfar": tfar}

    def __del__(self):
        lib = getattr(self, "_lib", None)
        if lib is not None and getattr(self, "scene", None):
            lib.rtcReleaseScene(self.scene)
            for part in getattr(self, "_scenes", {}).values():
                lib.rtcReleaseScene(part)
