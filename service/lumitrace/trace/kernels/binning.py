"""Binning of escapes: the cube map's texel, the goniophotometer's C-gamma cell and exit
bin of each, in vectorised chunks; the per-photon records' cell and slab masks."""
from __future__ import annotations

import math

import numba
import numpy as np

from .jit import _ALWAYS, _INLINE, _JIT
from .maths import _apply9, _rows

# --- binning of escapes ---------------------------------------------------------------------

# Escapes are binned in chunks (:func:`_bin_escapes`): a first loop computes every escape's
# face and pixel, angles and exit with selects, no branches, so LLVM runs it on several
# escapes at once; a second adds the counts. Binned one by one, the random directions'
# mispredicted branches cost three times as much.

@numba.njit(**_ALWAYS)
def _texel_pixel(x, y, z, res):
    """Cube-map face (0..5: +x, -x, +y, -y, +z, -z) of direction (x, y, z) and its nearest
    pixel's two in-face positions, as :func:`lumitrace.film.cubemap.texel_index` has them
    (ImfEnvmap's face choice and pixel positions)."""
    ax, ay, az = abs(x), abs(y), abs(z)
    isx = (ax >= ay) & (ax >= az)
    isz = (ay < az) & ~isx
    major = x if isx else (z if isz else y)
    a = y if isx else x
    b = z if isx else (y if isz else z)
    face = (0 if isx else (4 if isz else 2)) + (major <= 0.0)
    amax = abs(major)
    zero = amax == 0.0
    s = float(res - 1)
    pa = (a / (1.0 if zero else amax) + 1.0) * (0.5 * s)
    pb = (b / (1.0 if zero else amax) + 1.0) * (0.5 * s)
    pa = 0.0 if (pa < 0.0) | zero else (s if pa > s else pa)
    pb = 0.0 if (pb < 0.0) | zero else (s if pb > s else pb)
    return 0 if zero else face, int(pa + 0.5), int(pb + 0.5)  # (>= 0.5: int() is floor())


@numba.njit(**_INLINE)
def _texel_index(face, ia, ib, res, layout):
    """The texel of pixel (``ia``, ``ib``) of ``face``; ``layout`` holds the rows c0, cx,
    cy, r0, rx, ry of :mod:`lumitrace.film.cubemap`'s pixel placement per face."""
    s = res - 1
    col = s * layout[0, face] + layout[1, face] * ia + layout[2, face] * ib
    row = face * res + s * layout[3, face] + layout[4, face] * ia + layout[5, face] * ib
    return row * res + col


@numba.njit(**_ALWAYS)
def _texel(x, y, z, res, layout):
    """Cube-map texel of direction (x, y, z), as :func:`lumitrace.film.cubemap.texel_index`."""
    face, ia, ib = _texel_pixel(x, y, z, res)
    return _texel_index(face, ia, ib, res, layout)


@numba.njit(**_JIT)
def texels(d, res, layout):
    """Cube-map texels (N,) of directions ``d`` (3, N); ``layout`` is (6, 6) int64 rows
    c0, cx, cy, r0, rx, ry of :mod:`lumitrace.film.cubemap`."""
    out = np.empty(d.shape[1], np.int64)
    for i in range(d.shape[1]):
        out[i] = _texel(d[0, i], d[1, i], d[2, i], res, layout)
    return out


@numba.njit(**_INLINE)
def _acos_fast(x):
    """acos of ``x`` in [-1, 1] within 2.2e-8 rad (Abramowitz and Stegun 4.4.46)."""
    a = abs(x)
    r = math.sqrt(1.0 - a) * (((((((-0.0012624911 * a + 0.0066700901) * a - 0.0170881256) * a
                                  + 0.0308918810) * a - 0.0501743046) * a + 0.0889789874) * a
                               - 0.2145988016) * a + 1.5707963050)
    return r if x >= 0.0 else math.pi - r


@numba.njit(**_INLINE)
def _atan2_fast(y, x):
    """atan2 within 1.4e-8 rad (Abramowitz and Stegun 4.4.49 on the octant's ratio)."""
    ax, ay = abs(x), abs(y)
    mx, mn = max(ax, ay), min(ax, ay)
    t = mn / mx if mx > 0.0 else 0.0
    s = t * t
    r = t * (1.0 + s * (-0.3333314528 + s * (0.1999355085 + s * (-0.1420889944 + s * (
        0.1065626393 + s * (-0.0752896400 + s * (0.0429096138 + s * (
            -0.0161657367 + s * 0.0028662257))))))))
    if ay > ax:
        r = 0.5 * math.pi - r
    if x < 0.0:
        r = math.pi - r
    return -r if y < 0.0 else r


#: How near (in cells) an approximate angle may come to a cell edge before the exact one
#: decides: far above the fast angles' error (2.2e-8 rad, 5e-6 of a 0.25 deg cell).
_EDGE_MARGIN = 1e-4


@numba.njit(**_ALWAYS)
def _gonio_angles(x, y, z, m):
    """gamma and C (deg, C in [0, 360)) of world direction (x, y, z) in the photometric
    axes ``m`` (:func:`_rows`), by the fast angles (within 2.2e-8 rad)."""
    px, py, pz = _apply9(m, x, y, z)
    gamma = math.degrees(_acos_fast(min(max(-pz, -1.0), 1.0)))
    c = math.degrees(_atan2_fast(py, px))
    return gamma, c + 360.0 if c < 0.0 else c


@numba.njit(**_INLINE)
def _edges4(extra_edges):
    """Up to four extra gamma edges (deg) as a 4-tuple, padded with inf: in registers, and
    no array reference counted in the loop that uses them."""
    n = extra_edges.shape[0]
    return (extra_edges[0] if n > 0 else math.inf, extra_edges[1] if n > 1 else math.inf,
            extra_edges[2] if n > 2 else math.inf, extra_edges[3] if n > 3 else math.inf)


@numba.njit(**_ALWAYS)
def _gonio_cell_fast(gamma, c, extra_edges, c_scale, g_scale, n_c, n_gamma):
    """The C-gamma cell of fast angles ``gamma``, ``c``, and whether they lie so near a
    cell edge that the exact angles must decide (selects only: several at once)."""
    gs, cs = gamma * g_scale, c * c_scale  # both >= 0: int() is floor()
    g = int(gs)
    fg, fc = gs - g, cs - int(cs)
    near = (fg < _EDGE_MARGIN) | (fg > 1.0 - _EDGE_MARGIN) | (fc < _EDGE_MARGIN) | \
        (fc > 1.0 - _EDGE_MARGIN)
    for e in extra_edges:
        near |= abs(gamma - e) * g_scale < _EDGE_MARGIN
        g += gamma >= e
    return min(int(cs), n_c - 1) * n_gamma + min(g, n_gamma - 1), near


@numba.njit(**_ALWAYS)
def _gonio_cell_at(gamma, c, x, y, z, m, extra_edges, c_scale, g_scale, n_c, n_gamma):
    """The C-gamma cell of world direction (x, y, z) from its fast angles ``gamma``, ``c``
    where they are far from every cell edge, else from :func:`_gonio_cell_exact`, so the
    cell is always the exact one (libm's acos and atan2 cost half of an escape)."""
    cell, near = _gonio_cell_fast(gamma, c, extra_edges, c_scale, g_scale, n_c, n_gamma)
    if near:
        px, py, pz = _apply9(m, x, y, z)
        return _gonio_cell_exact(px, py, pz, extra_edges, c_scale, g_scale, n_c, n_gamma)
    return cell


@numba.njit(**_ALWAYS)
def _gonio_cell(x, y, z, m, extra_edges, c_scale, g_scale, n_c, n_gamma):
    """The goniophotometer's C-gamma cell of world direction (x, y, z)."""
    gamma, c = _gonio_angles(x, y, z, m)
    return _gonio_cell_at(gamma, c, x, y, z, m, extra_edges, c_scale, g_scale, n_c, n_gamma)


@numba.njit(**_INLINE)
def _gonio_cell_exact(px, py, pz, extra_edges, c_scale, g_scale, n_c, n_gamma):
    """The C-gamma cell of direction ``p`` (photometric axes), by libm's angles."""
    gamma = math.degrees(math.acos(min(max(-pz, -1.0), 1.0)))
    g = int(gamma * g_scale)
    for e in extra_edges:
        if gamma >= e:
            g += 1
    c = math.degrees(math.atan2(py, px))
    if c < 0.0:
        c += 360.0
    return min(int(c * c_scale), n_c - 1) * n_gamma + min(g, n_gamma - 1)


@numba.njit(**_INLINE)
def _far_side(q, e, lo, hi):
    """Distance from ``q`` along ``e`` to the far side of the slab ``lo``..``hi`` (inf
    when parallel), by selects rather than branches: ray directions are random."""
    u = (lo - q) / e
    v = (hi - q) / e
    return math.inf if e == 0.0 else (v if v > u else u)


@numba.njit(**_ALWAYS)
def _gonio_exit(qx, qy, qz, x, y, z, m, lo, hi, side, n_cells):
    """The exit bin (offset by ``n_cells``) where the ray from world point ``q`` (m) along
    ``(x, y, z)`` leaves the goniophotometer's box (``lo``, ``hi``: 3-tuples in the
    photometric axes ``m``, see :func:`_rows`), and the distance (m) to where it leaves it
    (0 if behind)."""
    q0, q1, q2 = _apply9(m, qx, qy, qz)
    e0, e1, e2 = _apply9(m, x, y, z)
    lo0, lo1, lo2 = lo
    hi0, hi1, hi2 = hi
    t0 = _far_side(q0, e0, lo0, hi0)
    t1 = _far_side(q1, e1, lo1, hi1)
    t2 = _far_side(q2, e2, lo2, hi2)
    a1 = t1 < t0  # leaves across axis 1 (first on ties) ...
    t = t1 if a1 else t0
    a2 = t2 < t  # ... or axis 2
    t = t2 if a2 else t
    t = t if t > 0.0 else 0.0
    # in-face axes: C0 faces (axis 0) use (C90, up), C90 faces (C0, up), up faces (C0, C90)
    not0 = a1 | a2
    qa, ea = (q0 if not0 else q1), (e0 if not0 else e1)
    la, ha = (lo0 if not0 else lo1), (hi0 if not0 else hi1)
    qb, eb = (q1 if a2 else q2), (e1 if a2 else e2)
    lb, hb = (lo1 if a2 else lo2), (hi1 if a2 else hi2)
    up = (e2 if a2 else (e1 if a1 else e0)) > 0.0
    face = (0 if a2 else (4 if a1 else 2)) + up
    pa, pb = qa + t * ea, qb + t * eb
    pa = la if pa < la else (ha if pa > ha else pa)
    pb = lb if pb < lb else (hb if pb > hb else pb)
    ra, rb = ha - la, hb - lb
    uu = (pa - la) / (ra if ra > 1e-12 else 1e-12)
    vv = (pb - lb) / (rb if rb > 1e-12 else 1e-12)
    col = min(int(uu * side), side - 1)
    row = min(int(vv * side), side - 1)
    return n_cells + (face * side + row) * side + col, t


#: Escapes binned together (:func:`_bin_escapes`): their rows stay in the L1 cache.
_CHUNK = 256


@numba.njit(**_JIT)
def _bin_escapes(m, staged, sbin, ang, pix, first, res, layout, counts, axes, extra_edges,
                 c_scale, g_scale, n_c, n_gamma, lo, hi, side, n_bins, escaped, spectral,
                 escaped_xz, xz, records, rec_texel, rec_cell, rec_exit, exits, exit_pos,
                 exit_dir):
    """Bin ``m`` escapes, staged in ``staged`` (6, m: world start points (m), directions)
    and ``sbin`` (2, m: batch rows, halves): count their texels in ``counts`` (and X, Z in
    ``xz``), append their cells and exit bins to ``escaped`` from ``first``, fill their
    records and exit rays; returns the escaped bins written. ``ang`` (3, m) and ``pix``
    (4, m) are scratch (separate arrays, so the first loop vectorises)."""
    n_cells = n_c * n_gamma
    mm = _rows(axes)
    edges = _edges4(extra_edges)
    lo3, hi3 = (lo[0], lo[1], lo[2]), (hi[0], hi[1], hi[2])
    for k in range(m):  # selects only: several escapes at once
        x, y, z = staged[3, k], staged[4, k], staged[5, k]
        pix[0, k], pix[1, k], pix[2, k] = _texel_pixel(x, y, z, res)
        gamma, c = _gonio_angles(x, y, z, mm)
        cell, near = _gonio_cell_fast(gamma, c, edges, c_scale, g_scale, n_c, n_gamma)
        ang[0, k], ang[1, k] = cell, near  # (a cell index is exact in a float64)
        pix[3, k], ang[2, k] = _gonio_exit(staged[0, k], staged[1, k], staged[2, k], x, y, z,
                                           mm, lo3, hi3, side, n_cells)
    for k in range(m):
        x, y, z = staged[3, k], staged[4, k], staged[5, k]
        row, half, ex = sbin[0, k], sbin[1, k], pix[3, k]
        tex = _texel_index(pix[0, k], pix[1, k], pix[2, k], res, layout)
        pix[0, k] = tex
        cell = np.int64(ang[0, k])
        if ang[1, k]:  # near a cell edge: the exact angles decide
            px, py, pz = _apply9(mm, x, y, z)
            cell = _gonio_cell_exact(px, py, pz, edges, c_scale, g_scale, n_c, n_gamma)
        j = first + 2 * k
        escaped[j] = cell + n_bins * half
        escaped[j + 1] = ex + n_bins * half
        if spectral:
            xz[half, tex] += escaped_xz[0, j >> 1]
            xz[2 + half, tex] += escaped_xz[1, j >> 1]
        if records:
            rec_texel[row] = tex
            rec_cell[row] = cell
            rec_exit[row] = ex - n_cells
        if exits:  # the exit ray: where it leaves the luminaire's box (world m)
            t = ang[2, k]
            exit_pos[row, 0] = staged[0, k] + t * x
            exit_pos[row, 1] = staged[1, k] + t * y
            exit_pos[row, 2] = staged[2, k] + t * z
            exit_dir[row, 0], exit_dir[row, 1], exit_dir[row, 2] = x, y, z
    for k in range(m):  # the texels' counts alone: their increments overlap
        counts[sbin[1, k], pix[0, k]] += 1
    return first + 2 * m


@numba.njit(**_JIT)
def gonio_bins(p, d, axes, lo, hi, extra_edges, c_step, g_step, n_c, n_gamma, side):
    """The goniophotometer's cells and exit bins (N,) of rays from ``p`` (3, N, world m)
    along unit ``d`` (3, N)."""
    n = d.shape[1]
    cell = np.empty(n, np.int64)
    ex = np.empty(n, np.int64)
    m, lo3, hi3 = _rows(axes), (lo[0], lo[1], lo[2]), (hi[0], hi[1], hi[2])
    edges = _edges4(extra_edges)
    for i in range(n):
        cell[i] = _gonio_cell(d[0, i], d[1, i], d[2, i], m, edges, 1.0 / c_step,
                              1.0 / g_step, n_c, n_gamma)
        ex[i], _ = _gonio_exit(p[0, i], p[1, i], p[2, i], d[0, i], d[1, i], d[2, i], m, lo3,
                               hi3, side, n_c * n_gamma)
    return cell, ex


# --- per-photon records' cell masks -------------------------------------------------------

@numba.njit(**_INLINE)
def _grid_index(x, lo, hi, n):
    return min(max(int(math.floor((x - lo) / (hi - lo) * n)), 0), n - 1)


@numba.njit(**_INLINE)
def _segment_mask(ax, ay, az, bx, by, bz, glo, ghi, gn, m0, m1, m2):
    """The cells of the record grid that the box of segment a -> b overlaps."""
    i0 = _grid_index(min(ax, bx), glo[0], ghi[0], gn[0])
    j0 = _grid_index(max(ax, bx), glo[0], ghi[0], gn[0])
    i1 = _grid_index(min(ay, by), glo[1], ghi[1], gn[1])
    j1 = _grid_index(max(ay, by), glo[1], ghi[1], gn[1])
    i2 = _grid_index(min(az, bz), glo[2], ghi[2], gn[2])
    j2 = _grid_index(max(az, bz), glo[2], ghi[2], gn[2])
    return m0[i0, j0] & m1[i1, j1] & m2[i2, j2]


@numba.njit(**_INLINE)
def _slab_bits(a, b, lo, hi):
    """The slabs (32 across lo..hi, a uint32 mask) that the interval a..b overlaps."""
    i = _grid_index(min(a, b), lo, hi, 32)
    j = _grid_index(max(a, b), lo, hi, 32)
    return numba.uint32(((numba.uint64(1) << numba.uint64(j - i + 1)) - numba.uint64(1))
                        << numba.uint64(i))


@numba.njit(**_INLINE)
def _mark_segment(rec_cells, rec_slabs, row, ax, ay, az, bx, by, bz, glo, ghi, gn, m0, m1,
                  m2):
    """Add segment a -> b to photon ``row``'s cell mask and its slab masks."""
    rec_cells[row] |= _segment_mask(ax, ay, az, bx, by, bz, glo, ghi, gn, m0, m1, m2)
    rec_slabs[row, 0] |= _slab_bits(ax, bx, glo[0], ghi[0])
    rec_slabs[row, 1] |= _slab_bits(ay, by, glo[1], ghi[1])
    rec_slabs[row, 2] |= _slab_bits(az, bz, glo[2], ghi[2])


@numba.njit(**_INLINE)
def _grid_exit(ox, oy, oz, dx, dy, dz, glo, ghi):
    """Where the ray from o along d leaves the record grid's box."""
    t = min(_far_side(ox, dx, glo[0], ghi[0]), _far_side(oy, dy, glo[1], ghi[1]),
            _far_side(oz, dz, glo[2], ghi[2]))
    t = t if t > 0.0 else 0.0
    return ox + t * dx, oy + t * dy, oz + t * dz


@numba.njit(**_JIT)
def add_bins(flat, bins, sign):
    """Add ``sign`` to the int64 counts ``flat`` at each of ``bins`` (int64 flat indices,
    a repeated one added as often): a batch's escapes into the goniophotometer's counts."""
    for i in range(bins.size):
        flat[bins[i]] += sign
