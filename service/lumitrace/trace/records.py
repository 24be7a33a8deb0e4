"""Per-photon records: what each traced photon did, in 40 bytes (48 in a spectral scene), so
that an edit can find the photons whose paths it can change and retrace exactly those.

- ``texel``: where it escaped (the cube-map texel), or :data:`ABSORBED` / :data:`CUT`;
- ``cell``, ``exit``: where the goniophotometer counted it (C-gamma cell, exit bin less
  :data:`~lumitrace.film.goniometer.N_CELLS`), when it escaped;
- ``segments``: how many path segments it had (for the segment statistics);
- ``parts``: a hash bitmask of the parts it hit (bit ``crc32(part path) % 64``);
- ``cells``: a bitmask of the cells of a 64-cell grid over the luminaire (pinned with the
  tracing frame, :class:`CellGrid`) that the bounding boxes of its path segments overlap
  (escaping segments clipped to the grid's box);
- ``slabs``: per axis of that grid's box, a bitmask of the 32 slabs across it that those
  boxes overlap: a part far from a path along any one axis is told apart from it even
  where the 64 cells are too coarse (a thin blade beside a path in the same cell);
- ``x``, ``z``: in a spectral scene, the X and Z it added when it escaped (fixed point, see
  :mod:`lumitrace.scene.spectra`); empty arrays otherwise.

Both masks are conservative: a collision of two parts on one bit, or a box wider than its
segment, only retraces a photon whose path then comes out the same.
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass, fields

import numpy as np

#: ``texel`` of a photon absorbed on a surface, and of one cut by the depth limit.
ABSORBED = -1
CUT = -2
#: Bytes of one photon's record, and what a spectral scene's records add.
RECORD_BYTES = 4 + 4 + 2 + 2 + 8 + 8 + 3 * 4
COLOUR_RECORD_BYTES = 4 + 4


@dataclass
class PhotonRecords:
    """Records of consecutive photons of one emitter (photon ``first + k`` at row ``k``)."""

    texel: np.ndarray  # int32
    cell: np.ndarray  # int32
    exit: np.ndarray  # uint16
    segments: np.ndarray  # uint16 (saturating)
    parts: np.ndarray  # uint64
    cells: np.ndarray  # uint64
    slabs: np.ndarray  # (N, 3) uint32
    x: np.ndarray  # int32, spectral scenes only (else empty)
    z: np.ndarray  # int32, spectral scenes only (else empty)

    @classmethod
    def empty(cls, n: int = 0, colour: bool = False) -> "PhotonRecords":
        c = n if colour else 0
        return cls(np.full(n, ABSORBED, np.int32), np.zeros(n, np.int32),
                   np.zeros(n, np.uint16), np.zeros(n, np.uint16),
                   np.zeros(n, np.uint64), np.zeros(n, np.uint64),
                   np.zeros((n, 3), np.uint32), np.zeros(c, np.int32), np.zeros(c, np.int32))

    @property
    def colour(self) -> bool:
        """Whether the records hold the photons' X and Z."""
        return len(self.x) == len(self.texel) and len(self.texel) > 0

    def _arrays(self) -> list[np.ndarray]:
        """The per-photon arrays (X and Z only where the records hold them)."""
        names = [f.name for f in fields(self)]
        return [getattr(self, n) for n in (names if self.colour else names[:-2])]

    def _make(self, arrays) -> "PhotonRecords":
        arrays = list(arrays)
        if len(arrays) < len(fields(self)):
            arrays += [np.zeros(0, np.int32)] * 2
        return PhotonRecords(*arrays)

    def __len__(self) -> int:
        return len(self.texel)

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in self._arrays())

    def extend(self, other: "PhotonRecords") -> "PhotonRecords":
        if not len(self) or not len(other):
            return other if len(other) else self
        return self._make(np.concatenate([a, b])
                          for a, b in zip(self._arrays(), other._arrays()))

    def take(self, rows: np.ndarray) -> "PhotonRecords":
        return self._make(a[rows] for a in self._arrays())

    def put(self, rows: np.ndarray, other: "PhotonRecords") -> None:
        for a, b in zip(self._arrays(), other._arrays()):
            a[rows] = b


def part_bit(path: str) -> np.uint64:
    """The bit of a part in the ``parts`` mask: a hash of its prim path (stable when other
    parts are added or removed)."""
    return np.uint64(1) << np.uint64(zlib.crc32(path.encode()) % 64)


def part_bits(parts: tuple[str, ...] | list[str]) -> np.ndarray:
    """The bit of every part, in the order of ``Scene.parts``."""
    return np.array([part_bit(p) for p in parts], dtype=np.uint64)


#: Cells of the grid (one bit each in ``cells``), and slabs across it per axis.
GRID_CELLS = 64
SLABS = 32
#: Room the grid leaves around the luminaire's bounds (normalised units: the frame's
#: largest half-extent is 1), so that an edit may grow or move a part a little.
GRID_MARGIN = 0.25


@dataclass(frozen=True)
class CellGrid:
    """A grid of at most :data:`GRID_CELLS` cells over a box of the normalised frame, with
    cells per axis chosen for the box's shape (a long luminaire gets more along its
    length): ``lo``, ``hi`` (normalised) and ``n`` cells per axis."""

    lo: tuple[float, float, float] = (-1.25, -1.25, -1.25)
    hi: tuple[float, float, float] = (1.25, 1.25, 1.25)
    n: tuple[int, int, int] = (4, 4, 4)

    @classmethod
    def around(cls, lo, hi) -> "CellGrid":
        """The grid over the bounds ``lo``..``hi`` (normalised) with their margin."""
        lo = np.asarray(lo, float) - GRID_MARGIN
        hi = np.asarray(hi, float) + GRID_MARGIN
        n = np.ones(3, int)
        while n.prod() * 2 <= GRID_CELLS:
            n[int(np.argmax((hi - lo) / n))] *= 2
        return cls(tuple(map(float, lo)), tuple(map(float, hi)), tuple(map(int, n)))

    def _index(self, x: np.ndarray) -> np.ndarray:
        lo, hi, n = (np.asarray(v)[:, None] for v in (self.lo, self.hi, self.n))
        return np.clip(np.floor((x - lo) / (hi - lo) * n), 0, n - 1).astype(np.int64)

    def box_cells(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Cell masks (N,) uint64 of boxes ``lo``..``hi`` (3, N), normalised."""
        a, b = self._index(lo), self._index(hi)
        masks = _axis_masks(self.n)
        return masks[0][a[0], b[0]] & masks[1][a[1], b[1]] & masks[2][a[2], b[2]]

    def segment_cells(self, o: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Cell masks of segments ``o`` -> ``p`` (3, N)."""
        return self.box_cells(np.minimum(o, p), np.maximum(o, p))

    def exit_points(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Where rays from ``o`` along ``d`` (3, N) leave the grid's box."""
        lo, hi = (np.asarray(v)[:, None] for v in (self.lo, self.hi))
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(d > 0, (hi - o) / d, np.where(d < 0, (lo - o) / d, np.inf))
        return o + np.maximum(np.min(t, axis=0), 0.0) * d

    def box_slabs(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Slab masks (N, 3) uint32 of boxes ``lo``..``hi`` (3, N), normalised."""
        a, b = (_slab_index(v, self.lo, self.hi) for v in (lo, hi))
        width = (b - a + 1).astype(np.uint64)
        masks = ((np.uint64(1) << width) - np.uint64(1)) << a.astype(np.uint64)
        return masks.T.astype(np.uint32)

    def triangle_slabs(self, triangles: np.ndarray) -> np.ndarray:
        """The union (3,) uint32 of the slabs the bounding boxes of ``triangles`` overlap."""
        if len(triangles) == 0:
            return np.zeros(3, np.uint32)
        return np.bitwise_or.reduce(self.box_slabs(triangles.min(axis=1).T,
                                                   triangles.max(axis=1).T), axis=0)

    def triangle_cells(self, triangles: np.ndarray) -> np.uint64:
        """The union of the cells the bounding boxes of ``triangles`` (T, 3, 3) overlap."""
        if len(triangles) == 0:
            return np.uint64(0)
        return np.bitwise_or.reduce(self.box_cells(triangles.min(axis=1).T,
                                                   triangles.max(axis=1).T))

    def inside(self, triangles: np.ndarray) -> bool:
        """Whether every triangle (T, 3, 3), normalised, lies within the grid's box."""
        if len(triangles) == 0:
            return True
        pts = triangles.reshape(-1, 3)
        return bool((pts >= np.array(self.lo)).all() and (pts <= np.array(self.hi)).all())


def _slab_index(x: np.ndarray, lo, hi) -> np.ndarray:
    """The slab (0..SLABS-1) of coordinates ``x`` (3, N) per axis of the box lo..hi."""
    lo, hi = (np.asarray(v, np.float64)[:, None] for v in (lo, hi))
    return np.clip(np.floor((x - lo) / (hi - lo) * SLABS), 0, SLABS - 1).astype(np.int64)


_MASKS: dict[tuple[int, int, int], list[np.ndarray]] = {}


def _axis_masks(n: tuple[int, int, int]) -> list[np.ndarray]:
    """Per axis, (lo, hi) -> the cells whose index on that axis lies in [lo, hi]."""
    if n not in _MASKS:
        cell = np.arange(n[0] * n[1] * n[2])
        coord = np.stack([cell % n[0], (cell // n[0]) % n[1], cell // (n[0] * n[1])])
        bits = np.left_shift(np.uint64(1), cell.astype(np.uint64))
        out = []
        for axis in range(3):
            m = np.zeros((n[axis], n[axis]), np.uint64)
            for lo in range(n[axis]):
                for hi in range(lo, n[axis]):
                    sel = (coord[axis] >= lo) & (coord[axis] <= hi)
                    m[lo, hi] = np.bitwise_or.reduce(bits[sel])
            out.append(m)
        _MASKS[n] = out
    return _MASKS[n]
