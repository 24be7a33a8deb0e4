"""The compiled photon work: emission, scattering, offsets and binning, without the GIL.

Between two Embree calls a photon needs a few hundred floating-point operations; done as
numpy array passes that cost more than the intersection itself (temporaries, gathers,
page faults). Here photons are handled in loops compiled by numba that call Embree's
``rtcIntersect1`` themselves: each photon is followed from its emission to its escape,
absorption or cut with its state in registers. An escape is binned into the cube map, the
goniophotometer's cell and exit bin (and the photon's record, when kept); a hit is offset
and scattered by its material's model. The same loop can instead advance a wave of
photons by one bounce, from Embree's hits of a batch of rays (for embreex).

Everything jitted lives in this one module: numba's on-disk cache is keyed by the file
of each entry point, so a helper in another file could change without its callers being
recompiled. Per photon the arithmetic is scalar float64, the same for any wave size,
batch size or thread, so maps stay bit-identical across them.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from ..scene import DIELECTRIC, DIFFUSE, GLOSSY, MIRROR, TRANSLUCENT
from .codes import DISK, MESH, MIXED, PRISTINE, RAYS, RECT, SPHERE
from .records import CUT
from .rng import _INV32, _LOW32, _M1, _M2, _S32, _S33, GOLDEN

_JIT = dict(nogil=True, cache=True, error_model="numpy")
_INLINE = _JIT  # small helpers: LLVM inlines them
_ALWAYS = dict(_JIT, inline="always")  # large helpers on the hot path, inlined by numba

# --- counter-based random numbers (bit-identical to :mod:`lumitrace.trace.rng`, whose
# constants they are: fixed for good, as every stored map depends on them) --------------
_GOLDEN = np.uint64(GOLDEN)
_ONE = np.uint64(1)




@numba.njit(**_INLINE)
def _fmix64(k):
    k = k ^ (k >> _S33)
    k = k * _M1
    k = k ^ (k >> _S33)
    k = k * _M2
    return k ^ (k >> _S33)


@numba.njit(**_INLINE)
def _uniform_pair(base, counter):
    """Two uniforms in [0, 1) of draw ``counter`` of the photon with hash ``base``."""
    h = _fmix64(base + numba.uint64(counter + 1) * _GOLDEN)
    return float(h >> _S32) * _INV32, float(h & _LOW32) * _INV32


# --- scalar vector helpers ----------------------------------------------------------------

@numba.njit(**_INLINE)
def _dot(ax, ay, az, bx, by, bz):
    return ax * bx + ay * by + az * bz


@numba.njit(**_INLINE)
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


#: Taylor coefficients of sin (x^3 .. x^15), cos (x^2 .. x^16): on [0, pi/4] to 5e-17.
_SIN = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(1, 8))
_COS = tuple((-1.0) ** k / math.factorial(2 * k) for k in range(1, 9))


@numba.njit(**_ALWAYS)
def _turn(u):
    """cos and sin of 2 pi ``u``, ``u`` in [0, 1), within 1e-15 by polynomials after an
    exact reduction: faster than libm's cos, and the same bits on every machine."""
    q = 4.0 * u
    k = int(q)
    r = q - k  # exact
    flip = r > 0.5
    x = (1.0 - r if flip else r) * (0.5 * math.pi)  # in [0, pi/4]
    x2 = x * x
    s = x + x * x2 * (_SIN[0] + x2 * (_SIN[1] + x2 * (_SIN[2] + x2 * (_SIN[3] + x2 * (
        _SIN[4] + x2 * (_SIN[5] + x2 * _SIN[6]))))))
    c = 1.0 + x2 * (_COS[0] + x2 * (_COS[1] + x2 * (_COS[2] + x2 * (_COS[3] + x2 * (
        _COS[4] + x2 * (_COS[5] + x2 * (_COS[6] + x2 * _COS[7])))))))
    if flip:
        s, c = c, s
    if k == 0:
        return c, s
    if k == 1:
        return -s, c
    if k == 2:
        return -c, -s
    return s, -c


@numba.njit(**_INLINE)
def _basis(nx, ny, nz):
    """Two unit tangents completing unit ``n`` to a right-handed frame (Duff et al. 2017)."""
    sign = math.copysign(1.0, nz)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx), (b, sign + ny * ny * a, -ny)


@numba.njit(**_INLINE)
def _to_world(lx, ly, lz, nx, ny, nz):
    """Local (z along unit ``n``) to world."""
    t, b = _basis(nx, ny, nz)
    return (lx * t[0] + ly * b[0] + lz * nx, lx * t[1] + ly * b[1] + lz * ny,
            lx * t[2] + ly * b[2] + lz * nz)


@numba.njit(**_ALWAYS)
def _cosine_local(u1, u2):
    """A cosine-weighted direction about +z (pdf cos / pi per sr)."""
    st = math.sqrt(u1)
    c, s = _turn(u2)
    return st * c, st * s, math.sqrt(max(0.0, 1.0 - u1))


@numba.njit(**_ALWAYS)
def _cosine_about(nx, ny, nz, u1, u2):
    """A cosine-weighted direction about unit ``n`` (pdf cos / pi per sr)."""
    lx, ly, lz = _cosine_local(u1, u2)
    return _to_world(lx, ly, lz, nx, ny, nz)


@numba.njit(**_INLINE)
def _reflect(dx, dy, dz, nx, ny, nz):
    k = 2.0 * _dot(dx, dy, dz, nx, ny, nz)
    return dx - k * nx, dy - k * ny, dz - k * nz


@numba.njit(**_INLINE)
def _random_polarisation(dx, dy, dz, u):
    """Unpolarised light: a uniformly random unit direction across ``d``."""
    t, b = _basis(dx, dy, dz)
    c, s = _turn(0.5 * u)
    return c * t[0] + s * b[0], c * t[1] + s * b[1], c * t[2] + s * b[2]


@numba.njit(**_INLINE)
def _s_p(dx, dy, dz, nx, ny, nz, px, py, pz):
    """The s direction of the plane of incidence of ``d`` on ``n`` and the (s, p)
    components of the polarisation ``p`` (at normal incidence s is along ``p``)."""
    sx, sy, sz = _cross(dx, dy, dz, nx, ny, nz)
    ls = math.sqrt(_dot(sx, sy, sz, sx, sy, sz))
    if ls > 1e-12:
        sx, sy, sz = sx / ls, sy / ls, sz / ls
    else:
        sx, sy, sz = px, py, pz
    qx, qy, qz = _cross(sx, sy, sz, dx, dy, dz)
    return sx, sy, sz, _dot(px, py, pz, sx, sy, sz), _dot(px, py, pz, qx, qy, qz)


@numba.njit(**_INLINE)
def _polarise(sx, sy, sz, c, sn, amp_s, amp_p, ox, oy, oz, fx, fy, fz):
    """The polarisation of a wave leaving along ``o`` with s and p amplitudes."""
    qx, qy, qz = _cross(sx, sy, sz, ox, oy, oz)
    a, b = amp_s * c, amp_p * sn
    ex, ey, ez = a * sx + b * qx, a * sy + b * qy, a * sz + b * qz
    le = math.sqrt(_dot(ex, ey, ez, ex, ey, ez))
    if le > 1e-12:
        return ex / le, ey / le, ez / le
    return fx, fy, fz


@numba.njit(**_INLINE)
def _metal_polarisation(dx, dy, dz, nx, ny, nz, px, py, pz, ox, oy, oz):
    """The polarisation after an ideal metallic reflection (r_s = -1, r_p = 1) about ``n``."""
    sx, sy, sz, c, sn = _s_p(dx, dy, dz, nx, ny, nz, px, py, pz)
    return _polarise(sx, sy, sz, c, sn, -1.0, 1.0, ox, oy, oz, px, py, pz)


@numba.njit(**_INLINE)
def _fresnel(cos_i, eta):
    """Fresnel amplitudes (r_s, r_p, t_s, t_p) and cos(theta_t) for ``eta = n1 / n2``."""
    sin2_t = eta * eta * max(0.0, 1.0 - cos_i * cos_i)
    if sin2_t >= 1.0:
        return -1.0, 1.0, 0.0, 0.0, 0.0
    cos_t = math.sqrt(max(0.0, 1.0 - sin2_t))
    a = eta * cos_i
    b = eta * cos_t
    return ((a - cos_t) / (a + cos_t), (cos_i - b) / (cos_i + b), 2.0 * a / (a + cos_t),
            2.0 * a / (cos_i + b), cos_t)


@numba.njit(**_INLINE)
def _smith_g1(cos_theta, alpha):
    if not cos_theta > 0.0:
        return 0.0
    c2 = min(max(cos_theta * cos_theta, 1e-300), 1.0)
    return 2.0 / (1.0 + math.sqrt(1.0 + alpha * alpha * (1.0 - c2) / c2))


@numba.njit(**_ALWAYS)
def _ggx_visible_normal(wx, wy, wz, alpha, u1, u2):
    """A GGX microfacet normal (local frame, z up) drawn from the normals visible from
    ``w`` (Heitz 2018, "Sampling the GGX distribution of visible normals")."""
    vx, vy, vz = alpha * wx, alpha * wy, wz
    lv = math.sqrt(vx * vx + vy * vy + vz * vz)
    vx, vy, vz = vx / lv, vy / lv, vz / lv
    lensq = vx * vx + vy * vy
    if lensq > 0.0:
        inv = 1.0 / math.sqrt(lensq)
        t1x, t1y = -vy * inv, vx * inv
    else:
        t1x, t1y = 1.0, 0.0
    t2x, t2y, t2z = _cross(vx, vy, vz, t1x, t1y, 0.0)
    r = math.sqrt(u1)
    cphi, sphi = _turn(u2)
    p1 = r * cphi
    s = 0.5 * (1.0 + vz)
    p2 = (1.0 - s) * math.sqrt(max(0.0, 1.0 - p1 * p1)) + s * r * sphi
    p3 = math.sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2))
    nx = p1 * t1x + p2 * t2x + p3 * vx
    ny = p1 * t1y + p2 * t2y + p3 * vy
    nz = p2 * t2z + p3 * vz
    ex, ey, ez = alpha * nx, alpha * ny, max(nz, 1e-12)
    le = math.sqrt(ex * ex + ey * ey + ez * ez)
    return ex / le, ey / le, ez / le


@numba.njit(**_ALWAYS)
def scatter_one(kind, refl, spec, trans, ior, alpha, dx, dy, dz, nx, ny, nz,
                u0, u1, u2, u3, polarised, px, py, pz):
    """One photon arriving along ``d`` at a surface of scattering model ``kind`` with unit
    geometric normal ``n`` (front = counter-clockwise): (survives, new direction, new
    polarisation). ``p`` is its polarisation (x NaN: unpolarised), used when ``polarised``.
    Analog: a photon survives with the probability of the material's albedo; one that
    cannot survive (at most that albedo) is not given a direction."""
    nan = math.nan
    if (u0 >= refl and kind == DIFFUSE) or (u0 >= refl + trans and kind == TRANSLUCENT) \
            or (u0 >= spec and kind == GLOSSY):  # (Smith's G1 is at most 1)
        return False, dx, dy, dz, nan, 0.0, 0.0
    cos_d = _dot(dx, dy, dz, nx, ny, nz)
    front = cos_d < 0.0
    fx, fy, fz = (nx, ny, nz) if front else (-nx, -ny, -nz)  # normal on the photon's side
    if kind == DIFFUSE:
        ox, oy, oz = _cosine_about(fx, fy, fz, u1, u2)
        return u0 < refl, ox, oy, oz, nan, 0.0, 0.0
    if kind == TRANSLUCENT:
        if u0 < refl:
            ox, oy, oz = _cosine_about(fx, fy, fz, u1, u2)
        else:
            ox, oy, oz = _cosine_about(-fx, -fy, -fz, u1, u2)
        return u0 < refl + trans, ox, oy, oz, nan, 0.0, 0.0
    if kind == MIRROR:
        ox, oy, oz = _reflect(dx, dy, dz, nx, ny, nz)
        if polarised:
            if math.isnan(px):
                px, py, pz = _random_polarisation(dx, dy, dz, u3)
            px, py, pz = _metal_polarisation(dx, dy, dz, nx, ny, nz, px, py, pz, ox, oy, oz)
        return u0 < spec, ox, oy, oz, px, py, pz
    if kind == GLOSSY:
        t, b = _basis(fx, fy, fz)
        wx = -_dot(dx, dy, dz, t[0], t[1], t[2])
        wy = -_dot(dx, dy, dz, b[0], b[1], b[2])
        wz = max(-_dot(dx, dy, dz, fx, fy, fz), 1e-9)
        hx, hy, hz = _ggx_visible_normal(wx, wy, wz, alpha, u1, u2)
        k = 2.0 * (wx * hx + wy * hy + wz * hz)
        lx, ly, lz = k * hx - wx, k * hy - wy, k * hz - wz
        ox = lx * t[0] + ly * b[0] + lz * fx
        oy = lx * t[1] + ly * b[1] + lz * fy
        oz = lx * t[2] + ly * b[2] + lz * fz
        if polarised:
            if math.isnan(px):
                px, py, pz = _random_polarisation(dx, dy, dz, u3)
            mx = hx * t[0] + hy * b[0] + hz * fx
            my = hx * t[1] + hy * b[1] + hz * fy
            mz = hx * t[2] + hy * b[2] + hz * fz
            px, py, pz = _metal_polarisation(dx, dy, dz, mx, my, mz, px, py, pz, ox, oy, oz)
        return (u0 < spec * _smith_g1(lz, alpha)) and lz > 0.0, ox, oy, oz, px, py, pz
    if kind == DIELECTRIC:
        eta = 1.0 / ior if front else ior
        cos_i = abs(cos_d)
        rs, rp, ts, tp, cos_t = _fresnel(cos_i, eta)
        if not polarised or math.isnan(px):
            px, py, pz = _random_polarisation(dx, dy, dz, u3)
        sx, sy, sz, c, sn = _s_p(dx, dy, dz, fx, fy, fz, px, py, pz)
        if u0 < rs * rs * c * c + rp * rp * sn * sn:
            ox, oy, oz = _reflect(dx, dy, dz, fx, fy, fz)
            a_s, a_p = rs, rp
        else:
            k = eta * cos_i - cos_t
            ox, oy, oz = eta * dx + k * fx, eta * dy + k * fy, eta * dz + k * fz
            a_s, a_p = ts, tp
        px, py, pz = _polarise(sx, sy, sz, c, sn, a_s, a_p, ox, oy, oz, px, py, pz)
        return True, ox, oy, oz, px, py, pz
    return False, dx, dy, dz, px, py, pz  # ABSORBER


@numba.njit(**_JIT)
def scatter_many(kind, refl, spec, trans, ior, alpha, material, d, n, u0, u1, u2, u3,
                 pol, polarised, d_out, pol_out, alive):
    """:func:`scatter_one` over photons (3, N) of materials ``material`` (N,), into
    ``d_out``, ``pol_out`` (3, N) and ``alive`` (N,): the tracer's scattering, for tests."""
    for i in range(d.shape[1]):
        m = material[i]
        px = pol[0, i] if polarised else math.nan
        py = pol[1, i] if polarised else 0.0
        pz = pol[2, i] if polarised else 0.0
        ok, ox, oy, oz, qx, qy, qz = scatter_one(
            kind[m], refl[m], spec[m], trans[m], ior[m], alpha[m], d[0, i], d[1, i], d[2, i],
            n[0, i], n[1, i], n[2, i], u0[i], u1[i], u2[i], u3[i], polarised, px, py, pz)
        alive[i] = ok
        d_out[0, i], d_out[1, i], d_out[2, i] = ox, oy, oz
        pol_out[0, i], pol_out[1, i], pol_out[2, i] = qx, qy, qz


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


@numba.njit(**_INLINE)
def _rows(axes):
    """The photometric axes (3, 3) as a 9-tuple, row by row: held in registers, where
    array reads in a loop that writes other arrays keep LLVM from vectorising it."""
    return (axes[0, 0], axes[0, 1], axes[0, 2], axes[1, 0], axes[1, 1], axes[1, 2],
            axes[2, 0], axes[2, 1], axes[2, 2])


@numba.njit(**_INLINE)
def _apply9(m, x, y, z):
    """(x, y, z) in the axes ``m`` (a 9-tuple from :func:`_rows`)."""
    return (m[0] * x + m[1] * y + m[2] * z, m[3] * x + m[4] * y + m[5] * z,
            m[6] * x + m[7] * y + m[8] * z)


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
def _gonio_cell_at(gamma, c, x, y, z, m, extra_edges, c_scale, g_scale, n_c, n_gamma):
    """The C-gamma cell of world direction (x, y, z) from its fast angles ``gamma``, ``c``
    where they are far from every cell edge, else from :func:`_gonio_cell_exact`, so the
    cell is always the exact one (libm's acos and atan2 cost half of an escape)."""
    gs, cs = gamma * g_scale, c * c_scale  # both >= 0: int() is floor()
    g = int(gs)
    fg, fc = gs - g, cs - int(cs)
    near = (fg < _EDGE_MARGIN) | (fg > 1.0 - _EDGE_MARGIN) | (fc < _EDGE_MARGIN) | \
        (fc > 1.0 - _EDGE_MARGIN)
    for e in extra_edges:
        near |= abs(gamma - e) * g_scale < _EDGE_MARGIN
        g += gamma >= e
    if near:
        px, py, pz = _apply9(m, x, y, z)
        return _gonio_cell_exact(px, py, pz, extra_edges, c_scale, g_scale, n_c, n_gamma)
    return min(int(cs), n_c - 1) * n_gamma + min(g, n_gamma - 1)


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
        ang[0, k], ang[1, k] = _gonio_angles(x, y, z, mm)
        pix[3, k], ang[2, k] = _gonio_exit(staged[0, k], staged[1, k], staged[2, k], x, y, z,
                                           mm, lo3, hi3, side, n_cells)
    for k in range(m):
        x, y, z = staged[3, k], staged[4, k], staged[5, k]
        row, half, ex = sbin[0, k], sbin[1, k], pix[3, k]
        tex = _texel_index(pix[0, k], pix[1, k], pix[2, k], res, layout)
        counts[half, tex] += 1
        cell = _gonio_cell_at(ang[0, k], ang[1, k], x, y, z, mm, edges, c_scale, g_scale,
                              n_c, n_gamma)
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


# --- spectral photons -------------------------------------------------------------------
#
# A spectral photon carries a throughput per wavelength band, scaled so that its luminous
# weight (the sum over bands of the emitter's Y per band times the throughput) is 1: every
# photon still carries the same luminous flux, and Y stays a photon count. At a coloured
# surface it survives with the probability of its luminous albedo (the luminous weight of
# throughput times albedo) and its throughput is multiplied by the albedo over that
# probability, which keeps the weight at 1 and the estimate of every band unbiased. X and
# Z of an escape are then the sums over bands of the emitter's X and Z per band times the
# throughput: no wavelength is sampled, so a neutral path has exactly its light's colour.
# A dispersive dielectric must send each wavelength its own way: there the photon picks one
# band (with the probability of its luminous share, draw 2, which no bounce uses) and
# becomes monochromatic, its throughput 1 / Y of that band.
# A photon's band field says what its throughput is: PRISTINE, 1 in every band (nothing
# coloured met yet: its row is not even written, and neutral surfaces leave it so), MIXED
# (its row holds it), or a band: monochromatic, 1 / Y of that band (picked at a dispersive
# surface, or the wavelength of the ray a ray-file light drew it from; no row needed).

FIXED = 1 << 20  # = lumitrace.scene.spectra.FIXED_POINT


@numba.njit(**_INLINE)
def _luminous(tp, i, w, table, m):
    """Luminous weight of photon ``i``'s throughput times ``table[m]`` (per band)."""
    acc = 0.0
    for b in range(tp.shape[1]):
        acc += w[1, b] * tp[i, b] * table[m, b]
    return acc


@numba.njit(**_INLINE)
def _rescale(tp, i, j, table, m, p):
    """Row ``j`` := row ``i`` times ``table[m]`` / ``p`` (in place when i == j)."""
    for b in range(tp.shape[1]):
        tp[j, b] = tp[i, b] * table[m, b] / p


@numba.njit(**_INLINE)
def _fixed_xz(tp, i, band, w):
    """Photon ``i``'s X and Z, in 1/FIXED of its Y (integers: exact sums), by its state
    ``band``: a pristine photon's throughput is 1 in every band, a monochromatic one's
    1 / Y of its band."""
    if band >= 0:
        return (np.int64(round(w[0, band] / w[1, band] * FIXED)),
                np.int64(round(w[2, band] / w[1, band] * FIXED)))
    x, z = 0.0, 0.0
    for b in range(w.shape[1]):
        t = 1.0 if band == PRISTINE else tp[i, b]
        x += w[0, b] * t
        z += w[2, b] * t
    return np.int64(round(x * FIXED)), np.int64(round(z * FIXED))


@numba.njit(**_INLINE)
def _spectral_hit(m, kind, alpha, s_refl, s_spec, s_trans, s_ior, dispersive, neutral, w,
                  tp, tband, i, j, h, dx, dy, dz, nx, ny, nz, u0, u1, u2, u3, polarised,
                  px, py, pz):
    """:func:`scatter_one` for a spectral photon ``i`` on material ``m``, its new
    throughput written to row ``j`` (``j`` <= ``i``) if it survives."""
    band = tband[i]
    if band == PRISTINE and neutral[m]:  # nothing coloured met, nor here: as monochrome
        out = scatter_one(kind, s_refl[m, 0], s_spec[m, 0], s_trans[m, 0], s_ior[m, 0], alpha,
                          dx, dy, dz, nx, ny, nz, u0, u1, u2, u3, polarised, px, py, pz)
        tband[j] = PRISTINE
        return out
    if kind == DIELECTRIC and dispersive[m] and band < 0:
        # a dispersive surface: one band goes on, picked by its luminous share
        u, _ = _uniform_pair(h, 2)
        pick = w.shape[1] - 1
        acc = 0.0
        for b in range(w.shape[1]):
            acc += w[1, b] * (1.0 if band == PRISTINE else tp[i, b])
            if u < acc:
                pick = b
                break
        band = pick
    if band >= 0:  # monochromatic: its band's values, its throughput stays 1 / Y there
        out = scatter_one(kind, s_refl[m, band], s_spec[m, band], s_trans[m, band],
                          s_ior[m, band], alpha, dx, dy, dz, nx, ny, nz, u0, u1, u2, u3,
                          polarised, px, py, pz)
        tband[j] = band
        return out
    if band == PRISTINE:
        for b in range(tp.shape[1]):
            tp[i, b] = 1.0
        band = MIXED
    ior = s_ior[m, 0]
    refl = spec = trans = 0.0
    if kind == DIFFUSE or kind == TRANSLUCENT:
        refl = _luminous(tp, i, w, s_refl, m)
    if kind == TRANSLUCENT:
        trans = _luminous(tp, i, w, s_trans, m)
    if kind == MIRROR or kind == GLOSSY:
        spec = _luminous(tp, i, w, s_spec, m)
    alive, ox, oy, oz, qx, qy, qz = scatter_one(kind, refl, spec, trans, ior, alpha, dx, dy, dz,
                                                nx, ny, nz, u0, u1, u2, u3, polarised,
                                                px, py, pz)
    if alive:
        if kind == DIFFUSE or (kind == TRANSLUCENT and u0 < refl):
            _rescale(tp, i, j, s_refl, m, refl)
        elif kind == TRANSLUCENT:
            _rescale(tp, i, j, s_trans, m, trans)
        elif kind == MIRROR or kind == GLOSSY:
            _rescale(tp, i, j, s_spec, m, spec)
        elif j != i:
            for b in range(tp.shape[1]):
                tp[j, b] = tp[i, b]
        tband[j] = band
    return alive, ox, oy, oz, qx, qy, qz


# --- one bounce of a wave, or whole paths ----------------------------------------------------

@numba.njit(**_JIT)
def bounce(depth, last, prim, tfar, o, d, pol, base, pid, o2, d2, pol2, base2, pid2,
           o32, d32, normals, corners, material_index, part_index, kind, refl, spec, trans,
           ior, alpha, polarised, spectral, s_refl, s_spec, s_trans, s_ior, dispersive,
           neutral, band_w, tp, tband, xz, escaped_xz, counts, res, layout, escaped, n_escaped,
           part_hits, center, scale, axes, lo, hi, extra_edges, c_step, g_step, n_c, n_gamma,
           side, n_bins, records, rec_texel, rec_cell, rec_exit, rec_segments, rec_parts,
           rec_cells, rec_slabs, rec_x, rec_z, part_bit, glo, ghi, gn, m0, m1, m2, exits,
           exit_pos, exit_dir, epsilon, backoff, near_hit, deep, fn, scene, offsets, order,
           reach_lo, reach_hi):
    """Advance the wave of photons ``o``, ``d`` (N, 3, normalised frame), ``pol``, ``base``
    (hashes) and ``pid`` (rows of the batch), N = len(``prim``), by the Embree hits ``prim``, ``tfar``.

    Escapes are counted in ``counts`` (2, texels), their goniophotometer bins appended to
    ``escaped`` from ``n_escaped``; survivors are written compacted into ``o2`` .. ``pid2``
    and, as float32 rays, into ``o32``, ``d32``. With ``records`` each photon's record
    (rows ``pid``) is updated; with ``exits`` each escape's ray where it leaves the
    goniophotometer's box (world m) and its direction, at its row of ``exit_pos`` and
    ``exit_dir``. In a ``spectral`` scene each photon carries its spectral throughput
    ``tp`` (N, bands; compacted in place) and its state ``tband`` (see :func:`_spectral_hit`);
    an escape adds its fixed-point X and Z (``band_w``: the emitter's X, Y, Z per band) to
    ``xz`` (rows X, X, Z, Z of the two halves), ``escaped_xz`` (2, escapes) and its record.

    With ``deep`` each photon is instead followed to its end from its emission (``o``,
    ``d``, ``pol``: the start points, directions and surface normals (3, N), world, moved
    as :func:`start` moves them), its state in registers, each ray cast through Embree as it
    goes (``fn`` .. ``order``: see :func:`intersect`; 0: no geometry) unless it misses the
    box ``reach_lo``..``reach_hi``, as :func:`cull` has it; the same numbers are drawn, so
    the tallies are the same. Returns (survivors, escaped bins, cut, absorbed, segments).
    """
    n_out, cut, absorbed, segments = 0, 0, 0, 0
    n_parts = part_hits.shape[0]
    ray = np.empty(40, np.uint32)  # deep: an RTCRayHit, 16-byte aligned within
    k0 = ((16 - ray.ctypes.data % 16) % 16) // 4
    rf = ray[k0:].view(np.float32)
    ru = ray[k0:]
    addr = numba.uint64(ray.ctypes.data + 4 * k0)
    staged = np.empty((6, _CHUNK))  # escapes staged for binning, and its scratch
    sbin = np.empty((2, _CHUNK), np.int64)
    binning = (staged, sbin, np.empty((3, _CHUNK)), np.empty((4, _CHUNK), np.int64))
    bins = (res, layout, counts, axes, extra_edges, 1.0 / c_step, 1.0 / g_step, n_c,
            n_gamma, lo, hi, side, n_bins, escaped, spectral, escaped_xz, xz, records,
            rec_texel, rec_cell, rec_exit, exits, exit_pos, exit_dir)
    ns = 0
    for i in range(prim.shape[0]):
        h = base[i]
        step = depth
        if deep:  # emitted: unpolarised, in row i
            ox, oy, oz = _started(o, pol, i, center, scale, epsilon)
            dx, dy, dz = d[0, i], d[1, i], d[2, i]
            qx, qy, qz = math.nan, (math.nan if polarised else 0.0), \
                (math.nan if polarised else 0.0)
            row = j = i  # (j: where a survivor's spectral throughput goes)
            tri, t32 = np.int64(-1), np.inf
            if fn != 0 and _reaches((ox, oy, oz), (dx, dy, dz), reach_lo, reach_hi):
                tri, t32 = _closest(fn, scene, addr, rf, ru, ox, oy, oz, dx, dy, dz, offsets,
                                    order)
        else:
            ox, oy, oz = o[i, 0], o[i, 1], o[i, 2]
            dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
            qx = pol[i, 0] if polarised else math.nan
            qy = pol[i, 1] if polarised else 0.0
            qz = pol[i, 2] if polarised else 0.0
            row, j = pid[i], n_out
            tri, t32 = np.int64(prim[i]), np.float64(tfar[i])
        while True:
            segments += 1
            if records and rec_segments[row] < 65535:
                rec_segments[row] += 1
            if tri < 0:  # escaped: staged for binning, in the half its hash's lowest bit picks
                staged[0, ns] = ox * scale + center[0]
                staged[1, ns] = oy * scale + center[1]
                staged[2, ns] = oz * scale + center[2]
                staged[3, ns], staged[4, ns], staged[5, ns] = dx, dy, dz
                sbin[0, ns], sbin[1, ns] = row, int(h & _ONE)
                if spectral:
                    qx_, qz_ = _fixed_xz(tp, i, tband[i], band_w)
                    escaped_xz[0, (n_escaped >> 1) + ns] = qx_
                    escaped_xz[1, (n_escaped >> 1) + ns] = qz_
                    if records:
                        rec_x[row] = qx_
                        rec_z[row] = qz_
                ns += 1
                if ns == _CHUNK:
                    n_escaped = _bin_escapes(ns, *binning, n_escaped, *bins)
                    ns = 0
                if records:
                    qx, qy, qz = _grid_exit(ox, oy, oz, dx, dy, dz, glo, ghi)
                    _mark_segment(rec_cells, rec_slabs, row, ox, oy, oz, qx, qy, qz, glo, ghi,
                                  gn, m0, m1, m2)
                break
            if n_parts:
                part_hits[part_index[tri]] += 1
            # Embree's float32 tfar can put the hit a few ulps beyond the surface, behind an
            # adjoining face near an edge: back up along the ray (never beyond the origin)
            t = t32 - min(backoff, 0.5 * t32)
            px, py, pz = ox + t * dx, oy + t * dy, oz + t * dz
            nx, ny, nz = normals[tri, 0], normals[tri, 1], normals[tri, 2]
            if records:
                rec_parts[row] |= part_bit[tri]
                _mark_segment(rec_cells, rec_slabs, row, ox, oy, oz, px, py, pz, glo, ghi, gn,
                              m0, m1, m2)
            if step == last:
                cut += 1
                if records:
                    rec_texel[row] = CUT
                break
            cos_in = _dot(dx, dy, dz, nx, ny, nz)
            stay = False
            if t32 * abs(cos_in) < near_hit:
                # a hit at about the origin, on a face the float64 origin lies in front of
                # while the ray moves away from it, is float32 rounding: the photon goes on
                # unchanged
                rx = ox - corners[tri, 0]
                ry = oy - corners[tri, 1]
                rz = oz - corners[tri, 2]
                stay = _dot(rx, ry, rz, nx, ny, nz) * cos_in > 0.0
            if stay:
                alive = True
            else:
                m = material_index[tri]
                counter = (step + 1) * 4
                u0, u1 = _uniform_pair(h, counter)
                u2, u3 = _uniform_pair(h, counter + 1)
                if spectral:
                    alive, dx, dy, dz, qx, qy, qz = _spectral_hit(
                        m, kind[m], alpha[m], s_refl, s_spec, s_trans, s_ior, dispersive,
                        neutral, band_w, tp, tband, i, j, h, dx, dy, dz, nx, ny, nz, u0, u1,
                        u2, u3, polarised, qx, qy, qz)
                else:
                    alive, dx, dy, dz, qx, qy, qz = scatter_one(
                        kind[m], refl[m], spec[m], trans[m], ior[m], alpha[m], dx, dy, dz,
                        nx, ny, nz, u0, u1, u2, u3, polarised, qx, qy, qz)
            if not alive:
                absorbed += 1
                break
            side_sign = _dot(dx, dy, dz, nx, ny, nz)
            k = epsilon if side_sign > 0.0 else (-epsilon if side_sign < 0.0 else 0.0)
            px, py, pz = px + k * nx, py + k * ny, pz + k * nz
            if deep:  # on, from here
                ox, oy, oz = px, py, pz
                step += 1
                tri, t32 = _closest(fn, scene, addr, rf, ru, px, py, pz, dx, dy, dz, offsets,
                                    order)
                continue
            o2[n_out, 0], o2[n_out, 1], o2[n_out, 2] = px, py, pz
            d2[n_out, 0], d2[n_out, 1], d2[n_out, 2] = dx, dy, dz
            o32[n_out, 0], o32[n_out, 1], o32[n_out, 2] = px, py, pz
            d32[n_out, 0], d32[n_out, 1], d32[n_out, 2] = dx, dy, dz
            if polarised:
                pol2[n_out, 0], pol2[n_out, 1], pol2[n_out, 2] = qx, qy, qz
            base2[n_out] = h
            pid2[n_out] = row
            if spectral and stay:  # moved on unchanged: its throughput moves along
                tband[n_out] = tband[i]
                if tband[i] == MIXED:
                    for b in range(tp.shape[1]):
                        tp[n_out, b] = tp[i, b]
            n_out += 1
            break
    if ns:
        n_escaped = _bin_escapes(ns, *binning, n_escaped, *bins)
    return n_out, n_escaped, cut, absorbed, segments


@numba.njit(**_ALWAYS)
def _started(p, n, i, center, scale, epsilon):
    """Emitted photon ``i``'s origin (``p``, ``n``: start points and surface normals (3, N),
    world) in the normalised frame, off the emitting surface."""
    return ((p[0, i] - center[0]) / scale + epsilon * n[0, i],
            (p[1, i] - center[1]) / scale + epsilon * n[1, i],
            (p[2, i] - center[2]) / scale + epsilon * n[2, i])


@numba.njit(**_JIT)
def start(p, d, n, center, scale, epsilon, o, d_out, o32, d32):
    """Emitted photons into the first wave: origins moved into the normalised frame and
    off the emitting surface along its normal ``n`` (3, N), float32 rays beside them."""
    for i in range(p.shape[1]):
        x = _started(p, n, i, center, scale, epsilon)
        for k in range(3):
            o[i, k] = o32[i, k] = x[k]
            d_out[i, k] = d32[i, k] = d[k, i]



# --- emission -------------------------------------------------------------------------------


@numba.njit(**_INLINE)
def _profile_local(u1, u2, theta_tab, cdf):
    """A direction about +z drawn from a tabulated profile (inverse CDF, linear in theta)."""
    j = np.searchsorted(cdf, u1, side="right") - 1
    j = min(max(j, 0), cdf.shape[0] - 2)
    w = cdf[j + 1] - cdf[j]
    f = (u1 - cdf[j]) / w if w > 0.0 else 0.0
    theta = theta_tab[j] + min(max(f, 0.0), 1.0) * (theta_tab[j + 1] - theta_tab[j])
    st = math.sin(theta)
    c, s = _turn(u2)
    return st * c, st * s, math.cos(theta)


@numba.njit(**_INLINE)
def _measured_local(u1, u2, c_cdf, gamma_cdf, cos_edges, c_step):
    """A direction in a light's frame drawn from a measured profile's table (see
    :mod:`lumitrace.trace.profiles`): gamma from local -Z, C from local +X toward +Y."""
    m = c_cdf.shape[0] - 1
    j = min(max(np.searchsorted(c_cdf, u1, side="right") - 1, 0), m - 1)
    w = c_cdf[j + 1] - c_cdf[j]
    f = min(max((u1 - c_cdf[j]) / w, 0.0), 1.0) if w > 0.0 else 0.5
    row = gamma_cdf[j]
    n = row.shape[0] - 1
    k = min(max(np.searchsorted(row, u2, side="right") - 1, 0), n - 1)
    w2 = row[k + 1] - row[k]
    f2 = min(max((u2 - row[k]) / w2, 0.0), 1.0) if w2 > 0.0 else 0.5
    cg = cos_edges[k] + f2 * (cos_edges[k + 1] - cos_edges[k])  # uniform in solid angle
    sg = math.sqrt(max(0.0, 1.0 - cg * cg))
    c = (j + f) * c_step
    return sg * math.cos(c), sg * math.sin(c), -cg


@numba.njit(**_INLINE)
def _unit(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    return x / n, y / n, z / n


@numba.njit(**_INLINE)
def _apply(m, x, y, z):
    return (m[0, 0] * x + m[0, 1] * y + m[0, 2] * z, m[1, 0] * x + m[1, 1] * y + m[1, 2] * z,
            m[2, 0] * x + m[2, 1] * y + m[2, 2] * z)


@numba.njit(**_JIT)
def emit_photons(shape, size, point, shaped, theta_tab, cdf, measured, c_cdf, gamma_cdf,
                 cos_edges, c_step, mesh_cdf, mesh_tris, mesh_normals, two_sided, ray_cdf,
                 ray_pos, ray_dir, lin, offset, normal_map, key, index, p, d, n, base):
    """Photons ``index`` of one light: start points ``p`` (world m), unit directions ``d``
    and the emitting surface's unit normals ``n`` (3, N; world), and the photons' hashes
    ``base``. ``size`` is (radius, width, height, length) in the light's units; ``lin``,
    ``offset`` its world transform, ``normal_map`` the normals' (inverse transpose).
    ``shaped``: the UsdLux cone and focus table; ``measured``: a measured profile's table,
    which is the light's whole distribution (a disk or rect then emits on both sides).
    A mesh light picks a triangle by area (``mesh_cdf``), a point uniform on it and, if
    ``two_sided``, a side, from its first two numbers; a ray-file light picks one of its
    rays (start points ``ray_pos``, directions ``ray_dir``, local) by flux (``ray_cdf``)."""
    ax, ay, az = _unit(*_apply(normal_map, 0.0, 0.0, -1.0))
    for i in range(index.shape[0]):
        h = _fmix64(numba.uint64(index[i]) ^ key)
        base[i] = h
        u1, u2 = _uniform_pair(h, 0)
        u3, u4 = _uniform_pair(h, 1)
        if shape == DISK or shape == RECT:
            if shape == DISK:
                r = size[0] * math.sqrt(u1)
                c, s = _turn(u2)
                x, y, z = r * c, r * s, 0.0
            else:
                x, y, z = (u1 - 0.5) * size[1], (u2 - 0.5) * size[2], 0.0
            if measured:
                dx, dy, dz = _unit(*_apply(lin, *_measured_local(u3, u4, c_cdf, gamma_cdf,
                                                                 cos_edges, c_step)))
                side = 1.0 if dx * ax + dy * ay + dz * az >= 0.0 else -1.0
                nx, ny, nz = side * ax, side * ay, side * az
            else:
                if shaped:
                    lx, ly, lz = _profile_local(u3, u4, theta_tab, cdf)
                else:
                    lx, ly, lz = _cosine_local(u3, u4)
                dx, dy, dz = _to_world(lx, ly, lz, ax, ay, az)
                nx, ny, nz = ax, ay, az
        elif shape == SPHERE:
            if measured:
                wx, wy, wz = _measured_local(u1, u2, c_cdf, gamma_cdf, cos_edges, c_step)
            elif shaped:
                wx, wy, wz = _profile_local(u1, u2, theta_tab, cdf)
                wy, wz = -wy, -wz  # about the light's -Z
            else:
                ct = 1.0 - 2.0 * u1
                st = math.sqrt(max(0.0, 1.0 - ct * ct))
                c, s = _turn(u2)
                wx, wy, wz = st * c, st * s, ct
            dx, dy, dz = _unit(*_apply(lin, wx, wy, wz))
            if point:
                x, y, z = 0.0, 0.0, 0.0
                nx, ny, nz = dx, dy, dz
            else:
                lx, ly, lz = _cosine_local(u3, u4)
                x, y, z = _to_world(lx, ly, lz, wx, wy, wz)
                x, y, z = size[0] * x, size[0] * y, size[0] * z
                nx, ny, nz = _unit(*_apply(normal_map, x, y, z))
        elif shape == MESH:
            m = mesh_cdf.shape[0] - 1
            t = min(max(np.searchsorted(mesh_cdf, u1, side="right") - 1, 0), m - 1)
            w = mesh_cdf[t + 1] - mesh_cdf[t]
            f = min(max((u1 - mesh_cdf[t]) / w, 0.0), 1.0) if w > 0.0 else 0.5
            side = 1.0
            if two_sided:
                f, side = (2.0 * f, 1.0) if f < 0.5 else (2.0 * f - 1.0, -1.0)
            a = math.sqrt(f)
            b0, b1, b2 = 1.0 - a, a * (1.0 - u2), a * u2  # uniform on the triangle
            x = b0 * mesh_tris[t, 0, 0] + b1 * mesh_tris[t, 1, 0] + b2 * mesh_tris[t, 2, 0]
            y = b0 * mesh_tris[t, 0, 1] + b1 * mesh_tris[t, 1, 1] + b2 * mesh_tris[t, 2, 1]
            z = b0 * mesh_tris[t, 0, 2] + b1 * mesh_tris[t, 1, 2] + b2 * mesh_tris[t, 2, 2]
            nx, ny, nz = _apply(normal_map, side * mesh_normals[t, 0], side * mesh_normals[t, 1],
                                side * mesh_normals[t, 2])
            nx, ny, nz = _unit(nx, ny, nz)
            lx, ly, lz = _cosine_local(u3, u4)
            dx, dy, dz = _to_world(lx, ly, lz, nx, ny, nz)
        elif shape == RAYS:
            m = ray_cdf.shape[0] - 1
            t = min(max(np.searchsorted(ray_cdf, u1, side="right") - 1, 0), m - 1)
            x, y, z = ray_pos[t, 0], ray_pos[t, 1], ray_pos[t, 2]
            dx, dy, dz = _unit(*_apply(lin, ray_dir[t, 0], ray_dir[t, 1], ray_dir[t, 2]))
            nx, ny, nz = dx, dy, dz  # offset along the ray
        else:  # CYLINDER: its side, not its caps
            c, s = _turn(u2)
            x, y, z = (u1 - 0.5) * size[3], size[0] * c, size[0] * s
            nx, ny, nz = _unit(*_apply(normal_map, 0.0, c, s))
            lx, ly, lz = _cosine_local(u3, u4)
            dx, dy, dz = _to_world(lx, ly, lz, nx, ny, nz)
        wx, wy, wz = _apply(lin, x, y, z)
        p[0, i], p[1, i], p[2, i] = wx + offset[0], wy + offset[1], wz + offset[2]
        d[0, i], d[1, i], d[2, i] = dx, dy, dz
        n[0, i], n[1, i], n[2, i] = nx, ny, nz


@numba.njit(**_ALWAYS)
def _reaches(o, d, lo, hi):
    """Whether the ray from ``o`` along ``d`` (3-tuples) meets the box ``lo``..``hi``."""
    t0, t1 = 0.0, math.inf
    for a in range(3):
        if d[a] != 0.0:
            u = (lo[a] - o[a]) / d[a]
            v = (hi[a] - o[a]) / d[a]
            t0 = max(t0, min(u, v))
            t1 = min(t1, max(u, v))
        elif o[a] < lo[a] or o[a] > hi[a]:
            t1 = -1.0
    return t1 >= t0


@numba.njit(**_JIT)
def cull(n, o, d, base, pid, o32, d32, lo, hi):
    """Put the first ``n`` rays (o, d: (N, 3), normalised frame) that can meet the box
    ``lo``..``hi`` (the geometry's bounds, with a margin) first, the rest after them, moving
    their hashes, rows and float32 rays along; return how many can meet it. A ray that
    misses the box escapes without Embree."""
    k = 0
    for i in range(n):
        if not _reaches((o[i, 0], o[i, 1], o[i, 2]), (d[i, 0], d[i, 1], d[i, 2]), lo, hi):
            continue
        if i != k:
            for a in range(3):
                o[i, a], o[k, a] = o[k, a], o[i, a]
                d[i, a], d[k, a] = d[k, a], d[i, a]
                o32[i, a], o32[k, a] = o32[k, a], o32[i, a]
                d32[i, a], d32[k, a] = d32[k, a], d32[i, a]
            base[i], base[k] = base[k], base[i]
            pid[i], pid[k] = pid[k], pid[i]
        k += 1
    return k


# --- intersection ---------------------------------------------------------------------------

@intrinsic
def _call_void3(typingctx, fn, a, b, c):
    """Call the C function at address ``fn`` with three pointer arguments (addresses), no
    result: Embree's ``rtcIntersect1(scene, rayhit, args)``, whose address is known only
    at run time."""
    sig = types.void(types.uint64, types.uint64, types.uint64, types.uint64)

    def codegen(context, builder, signature, args):
        ptr = ir.IntType(8).as_pointer()
        f = builder.inttoptr(args[0], ir.FunctionType(ir.VoidType(), [ptr] * 3).as_pointer())
        builder.call(f, [builder.inttoptr(a, ptr) for a in args[1:]])
        return context.get_dummy_value()
    return sig, codegen


@numba.njit(**_ALWAYS)
def _closest(fn, scene, addr, f, u, ox, oy, oz, dx, dy, dz, offsets, order):
    """Embree's closest hit of one ray (made float32) through the RTCRayHit at ``addr``
    (``f``, ``u``: its words): the triangle (-1: none), its float32 distance (inf: none)."""
    f[0], f[1], f[2], f[3] = ox, oy, oz, 0.0  # origin, tnear
    f[4], f[5], f[6], f[7] = dx, dy, dz, 0.0  # direction, time
    f[8] = np.inf
    u[9], u[10], u[11] = 0xFFFFFFFF, 0, 0  # mask, id, flags
    u[18], u[19] = 0xFFFFFFFF, 0xFFFFFFFF  # no geometry, no instance
    _call_void3(fn, scene, addr, numba.uint64(0))
    if u[18] == 0xFFFFFFFF:
        return np.int64(-1), np.inf
    return np.int64(order[offsets[u[18]] + u[17]]), np.float64(f[8])


@numba.njit(**_JIT)
def intersect(fn, scene, o32, d32, offsets, order, prim, tfar):
    """Embree's closest hit of every float32 ray ``o32``, ``d32`` (N, 3) in ``scene`` (one
    geometry per part; triangle j of geometry g is ``order[offsets[g] + j]``): triangle
    ``prim`` (-1: none) and distance ``tfar`` (inf: none). ``fn``: ``rtcIntersect1``."""
    buf = np.empty(40, np.uint32)  # an RTCRayHit, 16-byte aligned within
    k = ((16 - buf.ctypes.data % 16) % 16) // 4
    f = buf[k:].view(np.float32)
    u = buf[k:]
    addr = numba.uint64(buf.ctypes.data + 4 * k)
    for i in range(o32.shape[0]):
        prim[i], tfar[i] = _closest(fn, scene, addr, f, u, o32[i, 0], o32[i, 1], o32[i, 2],
                                    d32[i, 0], d32[i, 1], d32[i, 2], offsets, order)
