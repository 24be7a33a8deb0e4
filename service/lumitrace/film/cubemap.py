"""The cube map: directions, texels and their solid angles, in OpenEXR's envmap layout.

The intensity map is an OpenEXR cube map exactly as ``ImfEnvmap`` (namespace ``CubeMap``)
defines it, so any OpenEXR-aware tool finds every direction where we put it.

Layout
------
The image is ``res`` pixels wide and ``6 * res`` tall (``res`` is ImfEnvmap's
``sizeOfFace``). The faces +X, -X, +Y, -Y, +Z, -Z are stacked top to bottom: face ``f``
occupies image rows ``f*res .. f*res + res - 1`` (``dataWindowForFace``). Arrays are
indexed ``image[row, col]``; ``row`` is the EXR ``y`` (down), ``col`` the EXR ``x``.

Pixel positions
---------------
ImfEnvmap works with a *position in face* ``pif = (px, py)``, both in ``[0, s]`` with
``s = res - 1``, and face coordinates ``(a, b) = pif / s * 2 - 1`` in ``[-1, 1]``
(``direction``; a single-pixel face, ``res == 1``, has ``(a, b) = (0, 0)``). Integer
positions are pixels, so the outermost pixel centres lie *on* the cube's edges and
corners: adjacent faces share their edge pixel positions. ``faceAndPixelPosition`` picks
the face of the major axis, with ties going to X before Y before Z, a zero component
counting as negative (``x > 0`` gives +X, else -X) and ``(0, 0, 0)`` mapping to +X at
``pif = (0, 0)``; then ``pif = (c / |major| + 1) / 2 * s`` for the two minor components
``c`` below. ``pixelPosition`` places ``pif`` in the image. With ``u = col / s * 2 - 1``
(left to right) and ``v = row_in_face / s * 2 - 1`` (top to bottom) the un-normalised
direction of a pixel is:

====  ====================  ========================  ============  ============
face  (a, b) = face coords  pixel (col, row_in_face)  direction     right / down
====  ====================  ========================  ============  ============
+X    (y, z) / |x|          (py, s - px)              ( 1, -v,  u)  +Z / -Y
-X    (y, z) / |x|          (s - py, s - px)          (-1, -v, -u)  -Z / -Y
+Y    (x, z) / |y|          (px, s - py)              ( u,  1, -v)  +X / -Z
-Y    (x, z) / |y|          (px, py)                  ( u, -1,  v)  +X / +Z
+Z    (x, y) / |z|          (s - px, s - py)          (-u, -v,  1)  -X / -Y
-Z    (x, y) / |z|          (px, s - py)              ( u, -v, -1)  +X / -Y
====  ====================  ========================  ============  ============

(``u = v = 0`` when ``res == 1``.) ``right / down`` is the axis a direction moves
towards when the pixel moves right (``col + 1``) or down (``row + 1``).

Texel footprints
----------------
A texel stands for the directions whose *nearest pixel position on their own face*
(the face ``faceAndPixelPosition`` picks, distance measured in face coordinates) is that
texel's: ``floor(pif + 0.5)`` componentwise (a direction exactly half way between two
pixel positions goes to the higher one). On a face the footprint of pixel ``i`` (per
axis) is the interval ``[(2i - 1 - s) / s, (2i + 1 - s) / s]`` of face coordinates
clipped to ``[-1, 1]``: interior pixels cover a full cell of width ``h = 2 / s``, edge
pixels the half cell between the edge and the first boundary, corner pixels a quarter
cell (``res == 1``: the whole face; ``res == 2``: a quadrant). The footprints
of all texels tile the sphere exactly once, so their solid angles sum to 4 pi. Texels of
different faces that share an edge position keep separate (half) footprints; a direction
exactly on an edge bins into the face ImfEnvmap prefers (X, then Y, then Z).
:func:`weld_seams` merges such duplicates where one continuous map is wanted.

The solid angle of the rectangle ``[a0, a1] x [b0, b1]`` on the face plane at unit
distance is ``F(a1, b1) - F(a0, b1) - F(a1, b0) + F(a0, b0)`` with
``F(a, b) = atan2(a * b, sqrt(1 + a**2 + b**2))`` (:func:`rectangle_solid_angle`, which
evaluates it without the cancellation of that sum).

All functions are vectorised numpy in float64 (positions, directions, solid angles in
steradians); texel indices are int64 flat indices ``row * res + col`` into the
``(6 * res, res)`` image.
"""
from __future__ import annotations

import functools

import numpy as np

from ..table_cache import kept_table

#: Number of faces and their names, in ImfEnvmap's ``CubeMapFace`` order (top to bottom).
NUM_FACES = 6
FACE_NAMES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
POS_X, NEG_X, POS_Y, NEG_Y, POS_Z, NEG_Z = range(NUM_FACES)
#: Major axis (0 = x, 1 = y, 2 = z) and its sign for each face.
FACE_AXIS = np.array([0, 0, 1, 1, 2, 2], dtype=np.int64)
FACE_SIGN = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
#: The two minor axes of each face, giving face coordinates (a, b) = (d[A], d[B]) / |d[major]|.
FACE_MINOR_AXES = np.array([[1, 2], [1, 2], [0, 2], [0, 2], [0, 1], [0, 1]], dtype=np.int64)

# ImfEnvmap's pixelPosition as affine maps, in units of s = res - 1:
#   col          = s * C0 + CX * px + CY * py
#   row_in_face  = s * R0 + RX * px + RY * py
_C0 = np.array([0, 1, 0, 0, 1, 0], dtype=np.int64)
_CX = np.array([0, 0, 1, 1, -1, 1], dtype=np.int64)
_CY = np.array([1, -1, 0, 0, 0, 0], dtype=np.int64)
_R0 = np.array([1, 1, 1, 0, 1, 1], dtype=np.int64)
_RX = np.array([-1, -1, 0, 0, 0, 0], dtype=np.int64)
_RY = np.array([0, 0, -1, 1, -1, -1], dtype=np.int64)


def _check_res(res: int) -> int:
    if isinstance(res, (bool, np.bool_)) or int(res) != res or res < 1:
        raise ValueError(f"cube map face size must be a positive integer, got {res!r}")
    return int(res)


def face_size(image_height: int) -> int:
    """Face size ``res`` of a cube map image ``image_height`` pixels tall.

    The image must be ``6 * res`` rows tall (and ``res`` columns wide); ImfEnvmap's
    ``sizeOfFace`` is ``min(width, height // 6)``, which is ``res`` for such an image.
    Raises ``ValueError`` when ``image_height`` is not a positive multiple of 6.
    """
    height = int(image_height)
    if height != image_height or height < NUM_FACES or height % NUM_FACES:
        raise ValueError(f"a cube map is 6 * res pixels tall; got a height of {image_height!r}")
    return height // NUM_FACES


def image_shape(res: int) -> tuple[int, int]:
    """Shape ``(6 * res, res)`` (rows, columns) of the cube map image with face size ``res``."""
    res = _check_res(res)
    return (NUM_FACES * res, res)


def _as_directions(directions) -> np.ndarray:
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"directions must be an array of shape (N, 3), got {d.shape}")
    if not np.isfinite(d).all():
        raise ValueError("directions contain NaN or Inf")
    return d


def face_and_pixel_position(directions, res: int) -> tuple[np.ndarray, np.ndarray]:
    """Face and continuous position in face of each direction (ImfEnvmap ``faceAndPixelPosition``).

    Parameters
    ----------
    directions : array_like, shape (N, 3)
        Directions, any length (not necessarily normalised), finite.
    res : int
        Face size in pixels.

    Returns
    -------
    face : ndarray, shape (N,), int64
        Face index 0..5 (+X, -X, +Y, -Y, +Z, -Z).
    pif : ndarray, shape (N, 2), float64
        Position in face ``(px, py)`` in pixels, each in ``[0, res - 1]``.
    """
    res = _check_res(res)
    d = _as_directions(directions)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
    is_x = (ax >= ay) & (ax >= az)
    is_z = ~is_x & (ay < az)
    is_y = ~is_x & ~is_z
    major = np.where(is_x, x, np.where(is_y, y, z))
    face = np.where(is_x, 0, np.where(is_y, 2, 4)) + (major <= 0)
    amax = np.abs(major)
    zero = amax == 0  # only (0, 0, 0): ImfEnvmap returns +X at (0, 0)
    s = res - 1
    pif = np.zeros((len(d), 2), dtype=np.float64)  # (where zero: 0, not what was there)
    # Minor components in ImfEnvmap's order: (y, z) on X faces, (x, z) on Y, (x, y) on Z.
    np.divide(np.where(is_x, y, x), amax, out=pif[:, 0], where=~zero)
    np.divide(np.where(is_z, y, z), amax, out=pif[:, 1], where=~zero)
    pif += 1.0
    pif *= 0.5 * s
    pif[zero] = 0.0
    face[zero] = POS_X
    # |minor| <= |major| keeps the ratio in [-1, 1]; clip only guards the last ulp.
    np.clip(pif, 0.0, float(s), out=pif)
    return face.astype(np.int64), pif


def pixel_position(face, pif, res: int) -> np.ndarray:
    """Image pixel position of a position in face (ImfEnvmap ``CubeMap::pixelPosition``).

    Parameters
    ----------
    face : array_like, shape (N,), int
        Face index 0..5.
    pif : array_like, shape (N, 2), float
        Position in face ``(px, py)`` in pixels.
    res : int
        Face size in pixels.

    Returns
    -------
    ndarray, shape (N, 2), float64
        ``(x, y)`` = (column, row) in the stacked ``(6 * res, res)`` image.
    """
    res = _check_res(res)
    f = np.asarray(face, dtype=np.int64)
    p = np.asarray(pif, dtype=np.float64).reshape(-1, 2)
    s = float(res - 1)
    x = s * _C0[f] + _CX[f] * p[:, 0] + _CY[f] * p[:, 1]
    y = f * res + s * _R0[f] + _RX[f] * p[:, 0] + _RY[f] * p[:, 1]
    return np.stack([x, y], axis=-1)


def _pif_of_pixel(rows, cols, res: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`pixel_position` for integer pixels: (face, px, py) as int64."""
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    s = res - 1
    face = rows // res
    rl = rows - face * res
    # Each face's map is a signed permutation of (px, py); invert it per face.
    c = cols - s * _C0[face]
    r = rl - s * _R0[face]
    # Solve [CX CY; RX RY] (px, py) = (c, r); the matrix is orthogonal with entries 0, +-1.
    px = _CX[face] * c + _RX[face] * r
    py = _CY[face] * c + _RY[face] * r
    return face, px, py


def direction(face, pif, res: int, normalize: bool = True) -> np.ndarray:
    """Direction of a position in face (ImfEnvmap ``CubeMap::direction``).

    Parameters
    ----------
    face : array_like, shape (N,), int
        Face index 0..5.
    pif : array_like, shape (N, 2), float
        Position in face ``(px, py)`` in pixels, in ``[0, res - 1]``.
    res : int
        Face size in pixels.
    normalize : bool
        Return unit vectors (default); ``False`` returns ImfEnvmap's vector on the cube,
        whose major component is exactly +-1.

    Returns
    -------
    ndarray, shape (N, 3), float64
    """
    res = _check_res(res)
    f = np.asarray(face, dtype=np.int64).reshape(-1)
    p = np.asarray(pif, dtype=np.float64).reshape(-1, 2)
    s = res - 1
    # (2 p - s) / s equals ImfEnvmap's p / s * 2 - 1 up to rounding and is exactly odd
    # under p -> s - p, which keeps symmetric texels exactly symmetric.
    ab = (2.0 * p - s) / s if s > 0 else np.zeros_like(p)
    d = np.empty((len(f), 3), dtype=np.float64)
    rows = np.arange(len(f))
    d[rows, FACE_AXIS[f]] = FACE_SIGN[f]
    d[rows[:, None], FACE_MINOR_AXES[f]] = ab
    if normalize:
        d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d


def texel_index(directions, res: int) -> np.ndarray:
    """Flat index of the texel whose footprint contains each direction (for binning).

    Parameters
    ----------
    directions : array_like, shape (N, 3)
        Directions, any length (not necessarily normalised), finite. ``(0, 0, 0)``
        maps where ImfEnvmap maps it (+X face, position in face (0, 0)).
    res : int
        Face size in pixels.

    Returns
    -------
    ndarray, shape (N,), int64
        ``row * res + col`` into the ``(6 * res, res)`` image, always in
        ``[0, 6 * res * res)``. The texel is the pixel nearest to the direction's position
        in face (``floor(pif + 0.5)``), see the module docstring.
    """
    res = _check_res(res)
    face, pif = face_and_pixel_position(directions, res)
    ip = np.floor(pif + 0.5).astype(np.int64)
    np.clip(ip, 0, res - 1, out=ip)
    s = res - 1
    col = s * _C0[face] + _CX[face] * ip[:, 0] + _CY[face] * ip[:, 1]
    row = face * res + s * _R0[face] + _RX[face] * ip[:, 0] + _RY[face] * ip[:, 1]
    return row * res + col


def texel_directions(res: int) -> np.ndarray:
    """Unit direction of every texel's pixel position (ImfEnvmap ``direction``, normalised).

    Returns
    -------
    ndarray, shape (6 * res, res, 3), float64
        ``[row, col]`` is the direction of image pixel ``(x = col, y = row)``. Edge and
        corner texels of adjacent faces have the same direction (shared positions).
    """
    res = _check_res(res)
    rows, cols = np.indices(image_shape(res))
    face, px, py = _pif_of_pixel(rows.ravel(), cols.ravel(), res)
    d = direction(face, np.stack([px, py], axis=-1), res)
    return d.reshape(NUM_FACES * res, res, 3)


def _footprint_bounds(res: int) -> np.ndarray:
    """Face-coordinate bounds of the footprints along one axis, shape (res + 1,)."""
    s = res - 1
    if s == 0:
        return np.array([-1.0, 1.0])
    k = np.arange(res + 1, dtype=np.float64)
    bounds = (2.0 * k - 1.0 - s) / s  # exact odd symmetry: bounds[res - k] == -bounds[k]
    bounds[0], bounds[-1] = -1.0, 1.0
    return bounds


def _triangle_solid_angle(a1, c1, a2, c2, a3, c3) -> np.ndarray:
    """Solid angle of the triangle with vertices ``(a_i, c_i, 1)`` (Van Oosterom-Strackee).

    ``tan(omega / 2) = det[R1 R2 R3] / (|R1||R2||R3| + (R1.R2)|R3| + (R1.R3)|R2| +
    (R2.R3)|R1|)``; with the vertices on the plane at unit distance the determinant is
    ``(a2 - a1)(c3 - c1) - (a3 - a1)(c2 - c1)``, computed from coordinate differences, so
    a small triangle keeps full relative precision.
    """
    det = (a2 - a1) * (c3 - c1) - (a3 - a1) * (c2 - c1)
    n1 = np.sqrt(1.0 + a1 * a1 + c1 * c1)
    n2 = np.sqrt(1.0 + a2 * a2 + c2 * c2)
    n3 = np.sqrt(1.0 + a3 * a3 + c3 * c3)
    den = (n1 * n2 * n3 + (a1 * a2 + c1 * c2 + 1.0) * n3 + (a1 * a3 + c1 * c3 + 1.0) * n2
           + (a2 * a3 + c2 * c3 + 1.0) * n1)
    return 2.0 * np.arctan2(np.abs(det), den)


def rectangle_solid_angle(a0, a1, b0, b1) -> np.ndarray:
    """Solid angle (sr) of the rectangle ``[a0, a1] x [b0, b1]`` on a cube face plane.

    The face plane is at unit distance; ``a``, ``b`` are face coordinates in ``[-1, 1]``
    (broadcasting arrays). Mathematically this is the closed form
    ``F(a1, b1) - F(a0, b1) - F(a1, b0) + F(a0, b0)`` with
    ``F(a, b) = atan2(a * b, sqrt(1 + a**2 + b**2))``; that four-term sum loses about
    ``eps / width**2`` relative precision on small texels (1e-9 at res 2048), so the same
    solid angle is evaluated as two spherical triangles, accurate to a few ulp.
    """
    a0, a1, b0, b1 = (np.asarray(x, dtype=np.float64) for x in (a0, a1, b0, b1))
    return (_triangle_solid_angle(a0, b0, a1, b0, a1, b1)
            + _triangle_solid_angle(a0, b0, a1, b1, a0, b1))


def face_solid_angles(res: int) -> np.ndarray:
    """Footprint solid angles of one face's pixels, indexed ``[py, px]`` (position in face).

    Returns
    -------
    ndarray, shape (res, res), float64, steradians
        The same for all six faces; exactly symmetric under ``px -> s - px``,
        ``py -> s - py`` and transposition. Sums to 2 pi / 3.
    """
    res = _check_res(res)
    b = _footprint_bounds(res)
    omega = rectangle_solid_angle(b[None, :-1], b[None, 1:], b[:-1, None], b[1:, None])
    # Make the eight symmetries exact by reading every texel from one representative.
    i = np.arange(res)
    fold = np.minimum(i, res - 1 - i)
    p, q = np.meshgrid(fold, fold, indexing="ij")
    return omega[np.maximum(p, q), np.minimum(p, q)]


def texel_solid_angles(res: int) -> np.ndarray:
    """Solid angle of every texel's footprint, in steradians.

    Returns
    -------
    ndarray, shape (6 * res, res), float64, read-only
        Positive; all texels together sum to 4 pi (to rounding, ~1e-13). Made once per
        face size and shared (1.2 ms at face size 64; every estimate of a map reads it).
    """
    return _texel_solid_angles(_check_res(res))


@functools.lru_cache(maxsize=2)
def _texel_solid_angles(res: int) -> np.ndarray:
    per_face = face_solid_angles(res)
    rows, cols = np.indices(image_shape(res))
    _, px, py = _pif_of_pixel(rows, cols, res)
    omega = per_face[py, px]
    omega.flags.writeable = False
    return omega


def canonical_texels(res: int) -> np.ndarray:
    """For each texel, the flat index of the texel ImfEnvmap maps its own direction to.

    Texels off the cube's edges map to themselves; edge texels shared by two faces and
    corner texels shared by three map to the one on the preferred face (X, then Y, then Z).

    Returns
    -------
    ndarray, shape (6 * res, res), int64
    """
    res = _check_res(res)
    return texel_index(texel_directions(res).reshape(-1, 3), res).reshape(image_shape(res))


@kept_table
def _seams(res: int) -> tuple[np.ndarray, np.ndarray]:
    """The canonical texel of every texel and which texels share their position: fixed
    by the face size, made once."""
    canon = canonical_texels(res).ravel()
    shared = np.bincount(canon, minlength=canon.size)[canon] > 1
    return canon, shared


def weld_seams(image, solid_angles=None) -> np.ndarray:
    """Merge texels that share a pixel position on a cube edge or corner.

    Each group of texels with the same position (2 on an edge, 3 at a corner) gets the
    solid-angle weighted mean of its values. For an intensity map (cd), this is the
    intensity over the union of their footprints: the full cell around the position.

    Parameters
    ----------
    image : array_like, shape (6 * res, res) or (6 * res, res, C)
    solid_angles : array_like, shape (6 * res, res), optional
        Weights; defaults to :func:`texel_solid_angles`.

    Returns
    -------
    ndarray, same shape as ``image``, float64
    """
    img = np.asarray(image, dtype=np.float64)
    res = face_size(img.shape[0])
    if img.shape[1] != res:
        raise ValueError(f"cube map image must be {6 * res} x {res}, got {img.shape[:2]}")
    w = texel_solid_angles(res) if solid_angles is None else np.asarray(solid_angles, np.float64)
    canon, shared = _seams(res)
    n = NUM_FACES * res * res
    flat = img.reshape(n, -1)
    wsum = np.bincount(canon, weights=w.ravel(), minlength=n)
    out = flat.copy()
    at = canon[shared]
    for ch in range(flat.shape[1]):
        num = np.bincount(canon, weights=flat[:, ch] * w.ravel(), minlength=n)
        out[shared, ch] = num[at] / wsum[at]
    return out.reshape(img.shape)


def bilinear_taps(directions, res: int) -> tuple[np.ndarray, np.ndarray]:
    """The four texels (4, N) and weights (4, N) of :func:`sample_map`'s bilinear lookup
    of ``directions`` (N, 3) in a map of face size ``res``: a lookup of many maps at the
    same directions computes them once. Tap by tap (rows), so that each gather reads one
    contiguous row of indices: a third of the time of gathering columns."""
    res = _check_res(res)
    face, pif = face_and_pixel_position(directions, res)
    s = res - 1
    i0 = np.clip(np.floor(pif), 0, max(s - 1, 0)).astype(np.int64)
    t = pif - i0
    i1 = np.minimum(i0 + 1, s)
    if s == 0:
        t[:] = 0.0

    def texel(ix, iy):
        col = s * _C0[face] + _CX[face] * ix + _CY[face] * iy
        row = face * res + s * _R0[face] + _RX[face] * ix + _RY[face] * iy
        return row * res + col

    tx, ty = t[:, 0], t[:, 1]
    index = np.stack([texel(i0[:, 0], i0[:, 1]), texel(i1[:, 0], i0[:, 1]),
                      texel(i0[:, 0], i1[:, 1]), texel(i1[:, 0], i1[:, 1])])
    weight = np.stack([(1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty])
    return index, weight


def sample_map(image, directions, taps: tuple[np.ndarray, np.ndarray] | None = None
               ) -> np.ndarray:
    """Bilinear lookup of a cube map by direction.

    The direction's position in face (ImfEnvmap ``faceAndPixelPosition``) is interpolated
    between the four surrounding pixel positions of its own face; since pixel positions
    reach the edges, no lookup ever crosses a face. The result is continuous across edges
    when shared edge texels hold equal values (see :func:`weld_seams`). Functions linear in
    the face coordinates are reproduced exactly.

    Parameters
    ----------
    image : array_like, shape (6 * res, res) or (6 * res, res, C)
        The cube map.
    directions : array_like, shape (N, 3)
        Directions, any length (not necessarily normalised), finite.
    taps : optional
        :func:`bilinear_taps` of ``directions`` for this face size, when made already.

    Returns
    -------
    ndarray, shape (N,) or (N, C), float64
    """
    img = np.asarray(image, dtype=np.float64)
    if img.ndim not in (2, 3):
        raise ValueError("cube map image must have shape (6*res, res) or (6*res, res, C)")
    res = face_size(img.shape[0])
    if img.shape[1] != res:
        raise ValueError(f"cube map image must be {6 * res} x {res}, got {img.shape[:2]}")
    index, weight = taps if taps is not None else bilinear_taps(directions, res)
    if img.ndim == 2:
        flat = img.ravel()
        return ((weight[0] * flat[index[0]] + weight[1] * flat[index[1]])
                + weight[2] * flat[index[2]]) + weight[3] * flat[index[3]]
    flat = img.reshape(NUM_FACES * res * res, -1)
    return ((weight[0, :, None] * flat[index[0]] + weight[1, :, None] * flat[index[1]])
            + weight[2, :, None] * flat[index[2]]) + weight[3, :, None] * flat[index[3]]


def latlong_directions(height: int, width: int | None = None) -> np.ndarray:
    """Unit directions of the pixels of a lat-long map (ImfEnvmap ``LatLongMap::direction``).

    Pixel ``(x, y)`` has latitude ``-pi * (y / (height - 1) - 0.5)`` and longitude
    ``-2 pi * (x / (width - 1) - 0.5)`` (the first row is +Y, latitude +pi/2; the first
    column longitude +pi) and direction ``(sin(lon) cos(lat), sin(lat), cos(lon) cos(lat))``.

    Returns
    -------
    ndarray, shape (height, width, 3), float64
        ``width`` defaults to ``2 * height``.
    """
    height = _check_res(height)
    width = 2 * height if width is None else _check_res(width)
    y = np.arange(height, dtype=np.float64)
    x = np.arange(width, dtype=np.float64)
    lat = -np.pi * (y / (height - 1) - 0.5) if height > 1 else np.zeros(1)
    lon = -2.0 * np.pi * (x / (width - 1) - 0.5) if width > 1 else np.zeros(1)
    lat, lon = np.meshgrid(lat, lon, indexing="ij")
    return np.stack([np.sin(lon) * np.cos(lat), np.sin(lat), np.cos(lon) * np.cos(lat)], -1)


__all__ = [
    "NUM_FACES", "FACE_NAMES", "FACE_AXIS", "FACE_SIGN", "FACE_MINOR_AXES",
    "POS_X", "NEG_X", "POS_Y", "NEG_Y", "POS_Z", "NEG_Z",
    "face_size", "image_shape", "face_and_pixel_position", "pixel_position", "direction",
    "texel_index", "texel_directions", "bilinear_taps", "face_solid_angles", "texel_solid_angles",
    "rectangle_solid_angle", "canonical_texels", "weld_seams", "sample_map", "latlong_directions",
]
