"""What one read of a stage hands the next: each mesh's triangles and each gprim's
placement, taken again where what they are made of is the same.

A live service reads its stage again after every edit. Without this, an edit of one
material or one part of a luminaire of a million triangles costs every mesh's
triangulation, placement and zero-area test again (and the memory that fresh arrays
fault in). Reuse is decided on the inputs themselves (the mesh's arrays compared, the
placement's matrix), never on change notices, so a read that reuses gives the same scene
as one that does not, array for array.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class _Triangulated:
    inputs: tuple          # points, counts, indices, kept faces, orientation
    triangles: np.ndarray  # (T, 3, 3) float64, local units, front faces counter-clockwise
    face: np.ndarray       # (T,) the face each triangle came from


@dataclass
class _Placed:
    local: np.ndarray      # the local triangles placed (the very array)
    matrix: np.ndarray     # row-vector local-to-world (stage units)
    meters_per_unit: float
    world: np.ndarray      # (K, 3, 3) world metres, zero-area triangles dropped
    keep: np.ndarray       # (T,) which local triangles are kept
    own: np.ndarray | None  # (K, 3, 3) float32: the kept ones in their own space


class ReadCache:
    """Meshes triangulated and gprims placed by earlier reads, one entry per prim path
    (the last read's)."""

    def __init__(self) -> None:
        self._triangulated: dict[str, _Triangulated] = {}
        self._placed: dict[str, _Placed] = {}

    def triangulated(self, path: str, inputs: tuple, make) -> tuple[np.ndarray, np.ndarray]:
        """(triangles, face of each) of the mesh at ``path`` made of ``inputs`` (arrays and
        tokens), by ``make()`` unless the last read's were made of equal inputs."""
        got = self._triangulated.get(path)
        if got is None or not _same(got.inputs, inputs):
            triangles, face = make()
            got = self._triangulated[path] = _Triangulated(inputs, triangles, face)
        return got.triangles, got.face

    def placed(self, path: str, local: np.ndarray, matrix: np.ndarray,
               meters_per_unit: float, make) -> tuple:
        """(world triangles kept, which local ones are kept, the kept ones in their own
        space) of ``local`` placed by ``matrix``, by ``make()`` unless the last read placed
        the same array by an equal matrix."""
        got = self._placed.get(path)
        if got is None or got.local is not local or got.meters_per_unit != meters_per_unit \
                or not np.array_equal(got.matrix, matrix):
            world, keep, own = make()
            got = self._placed[path] = _Placed(local, matrix.copy(), meters_per_unit, world,
                                               keep, own)
        return got.world, got.keep, got.own

    def keep_only(self, paths: set[str]) -> None:
        """Forget the prims a read no longer met (removed, deactivated, hidden)."""
        for table in (self._triangulated, self._placed):
            for path in set(table) - paths:
                del table[path]


def _same(a: tuple, b: tuple) -> bool:
    return len(a) == len(b) and all(
        (x.shape == y.shape and x.dtype == y.dtype and np.array_equal(x, y))
        if isinstance(x, np.ndarray) and isinstance(y, np.ndarray) else x == y
        for x, y in zip(a, b))
