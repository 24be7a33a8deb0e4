"""Per-photon records: what each traced photon did, in 22 bytes, so that an edit can find
the photons whose paths it can change and retrace exactly those.

- ``texel``: where it escaped (the cube-map texel), or :data:`ABSORBED` / :data:`CUT`;
- ``segments``: how many path segments it had (for the segment statistics);
- ``parts``: a hash bitmask of the parts it hit (bit ``crc32(part path) % 64``);
- ``cells``: a bitmask of the cells of a 4 x 4 x 4 grid over the normalised tracing frame
  that the bounding boxes of its path segments overlap (escaping segments clipped to the
  grid's box).

Both masks are conservative: a collision of two parts on one bit, or a box wider than its
segment, only retraces a photon whose path then comes out the same.
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

#: ``texel`` of a photon absorbed on a surface, and of one cut by the depth limit.
ABSORBED = -1
CUT = -2
#: Cells per axis of the grid over the normalised frame ([-GRID_HALF, GRID_HALF] cubed).
CELLS_PER_AXIS = 4
GRID_HALF = 1.25  # a margin around the frame (geometry lies in [-1, 1]): edits may grow it
#: Bytes of one photon's record.
RECORD_BYTES = 4 + 2 + 8 + 8


@dataclass
class PhotonRecords:
    """Records of consecutive photons of one emitter (photon ``first + k`` at row ``k``)."""

    texel: np.ndarray  # int32
    segments: np.ndarray  # uint16 (saturating)
    parts: np.ndarray  # uint64
    cells: np.ndarray  # uint64

    @classmethod
    def empty(cls, n: int = 0) -> "PhotonRecords":
        return cls(np.full(n, ABSORBED, np.int32), np.zeros(n, np.uint16),
                   np.zeros(n, np.uint64), np.zeros(n, np.uint64))

    def __len__(self) -> int:
        return len(self.texel)

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.texel, self.segments, self.parts, self.cells))

    def extend(self, other: "PhotonRecords") -> "PhotonRecords":
        return PhotonRecords(*(np.concatenate([a, b]) for a, b in zip(
            (self.texel, self.segments, self.parts, self.cells),
            (other.texel, other.segments, other.parts, other.cells))))

    def take(self, rows: np.ndarray) -> "PhotonRecords":
        return PhotonRecords(self.texel[rows], self.segments[rows], self.parts[rows],
                             self.cells[rows])

    def put(self, rows: np.ndarray, other: "PhotonRecords") -> None:
        self.texel[rows] = other.texel
        self.segments[rows] = other.segments
        self.parts[rows] = other.parts
        self.cells[rows] = other.cells


def part_bit(path: str) -> np.uint64:
    """The bit of a part in the ``parts`` mask: a hash of its prim path (stable when other
    parts are added or removed)."""
    return np.uint64(1) << np.uint64(zlib.crc32(path.encode()) % 64)


def part_bits(parts: tuple[str, ...] | list[str]) -> np.ndarray:
    """The bit of every part, in the order of ``Scene.parts``."""
    return np.array([part_bit(p) for p in parts], dtype=np.uint64)


def _axis_masks() -> np.ndarray:
    """(axis, lo, hi) -> the cells whose coordinate on ``axis`` lies in [lo, hi]."""
    n = CELLS_PER_AXIS
    cell = np.arange(n ** 3)
    coord = np.stack([cell % n, (cell // n) % n, cell // (n * n)])
    masks = np.zeros((3, n, n), np.uint64)
    for axis in range(3):
        for lo in range(n):
            for hi in range(lo, n):
                sel = (coord[axis] >= lo) & (coord[axis] <= hi)
                masks[axis, lo, hi] = np.bitwise_or.reduce(
                    np.left_shift(np.uint64(1), cell[sel].astype(np.uint64)))
    return masks


_AXIS_MASKS = _axis_masks()


def box_cells(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Cell masks (N,) uint64 of boxes ``lo``..``hi`` (3, N) in normalised coordinates."""
    n = CELLS_PER_AXIS
    scale = n / (2.0 * GRID_HALF)
    a = np.clip(np.floor((lo + GRID_HALF) * scale), 0, n - 1).astype(np.int64)
    b = np.clip(np.floor((hi + GRID_HALF) * scale), 0, n - 1).astype(np.int64)
    return (_AXIS_MASKS[0, a[0], b[0]] & _AXIS_MASKS[1, a[1], b[1]]
            & _AXIS_MASKS[2, a[2], b[2]])


def segment_cells(o: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Cell masks of segments ``o`` -> ``p`` (3, N)."""
    return box_cells(np.minimum(o, p), np.maximum(o, p))


def exit_points(o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Where rays from ``o`` along ``d`` (3, N) leave the grid's box (``o`` if outside)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d > 0, (GRID_HALF - o) / d, np.where(d < 0, (-GRID_HALF - o) / d, np.inf))
    t_exit = np.maximum(np.min(t, axis=0), 0.0)
    return o + t_exit * d


def triangle_cells(triangles: np.ndarray) -> np.uint64:
    """The union of the cells the bounding boxes of ``triangles`` (T, 3, 3), normalised,
    overlap."""
    if len(triangles) == 0:
        return np.uint64(0)
    masks = box_cells(triangles.min(axis=1).T, triangles.max(axis=1).T)
    return np.bitwise_or.reduce(masks)


def inside_grid(triangles: np.ndarray) -> bool:
    """Whether every triangle (T, 3, 3), normalised, lies within the grid's box."""
    return bool(len(triangles) == 0 or np.abs(triangles).max() <= GRID_HALF)
