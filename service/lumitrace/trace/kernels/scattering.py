"""Scattering of one photon at a surface by its material's model (diffuse, translucent,
mirror, GGX glossy, Fresnel dielectric), with its polarisation."""
from __future__ import annotations

import math

import numba

from ...scene import DIELECTRIC, DIFFUSE, GLOSSY, MIRROR, TRANSLUCENT
from .jit import _ALWAYS, _INLINE, _JIT
from .maths import _basis, _cosine_about, _cross, _dot, _reflect, _turn

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
