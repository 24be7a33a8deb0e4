"""Emission: photons' start points, directions and surface normals for every light kind
(disk, rect, sphere, point, cylinder, mesh, ray file; cone-shaped and measured
profiles), their move into the tracing frame, and the cull of rays that miss the geometry."""
from __future__ import annotations

import math

import numba
import numpy as np

from ..codes import CYLINDER, DISK, MESH, RAYS, RECT, SPHERE
from .jit import _ALWAYS, _INLINE, _JIT
from .maths import _apply9, _cosine_local, _fmix64, _rows, _to_world, _turn, _uniform_pair

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
    c3 = (center[0], center[1], center[2])  # in registers, as the lights' constants
    for i in range(p.shape[1]):
        x = _started(p, n, i, c3, scale, epsilon)
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
    rays (start points ``ray_pos``, directions ``ray_dir``, local) by flux (``ray_cdf``).

    Each family of lights has a loop of its own, with the family compiled in: LLVM then
    keeps only that family's path, where one loop over every light's branches ran 3-4x
    slower."""
    tables = (shape, size, point, shaped, theta_tab, cdf, measured, c_cdf, gamma_cdf,
              cos_edges, c_step, mesh_cdf, mesh_tris, mesh_normals, two_sided, ray_cdf,
              ray_pos, ray_dir, lin, offset, normal_map, key, index, p, d, n, base)
    tabulated = shaped or measured
    if shape == DISK or shape == RECT:
        if tabulated:
            _emit_loop(DISK, True, tables)
        else:
            _emit_loop(DISK, False, tables)
    elif shape == SPHERE:
        if tabulated:
            _emit_loop(SPHERE, True, tables)
        else:
            _emit_loop(SPHERE, False, tables)
    elif shape == MESH:
        _emit_loop(MESH, False, tables)
    elif shape == RAYS:
        _emit_loop(RAYS, False, tables)
    else:  # any other code: a cylinder, as ever
        _emit_loop(CYLINDER, False, tables)


@numba.njit(**_ALWAYS)
def _emit_loop(family, tabulated, tables):
    """:func:`emit_photons`' loop for one family of lights, constants where it is called:
    ``family`` DISK (a disk or a rect), SPHERE, MESH, RAYS or CYLINDER; ``tabulated``
    whether the light's profile is a table (shaped or measured)."""
    (shape, size, point, shaped, theta_tab, cdf, measured, c_cdf, gamma_cdf, cos_edges,
     c_step, mesh_cdf, mesh_tris, mesh_normals, two_sided, ray_cdf, ray_pos, ray_dir, lin,
     offset, normal_map, key, index, p, d, n, base) = tables
    # the light's constants in registers: read from their arrays, they would be read again
    # after each photon's writes (the arrays may alias), at several times the photon's cost
    lin9, nmap9, sz = _rows(lin), _rows(normal_map), (size[0], size[1], size[2], size[3])
    off3 = (offset[0], offset[1], offset[2])
    ax, ay, az = _unit(*_apply9(nmap9, 0.0, 0.0, -1.0))
    for i in range(index.shape[0]):
        h = _fmix64(numba.uint64(index[i]) ^ key)
        base[i] = h
        u1, u2 = _uniform_pair(h, 0)
        u3, u4 = _uniform_pair(h, 1)
        if family == DISK:
            if shape == DISK:
                r = sz[0] * math.sqrt(u1)
                c, s = _turn(u2)
                x, y, z = r * c, r * s, 0.0
            else:
                x, y, z = (u1 - 0.5) * sz[1], (u2 - 0.5) * sz[2], 0.0
            if tabulated and measured:
                dx, dy, dz = _unit(*_apply9(lin9, *_measured_local(u3, u4, c_cdf, gamma_cdf,
                                                                 cos_edges, c_step)))
                side = 1.0 if dx * ax + dy * ay + dz * az >= 0.0 else -1.0
                nx, ny, nz = side * ax, side * ay, side * az
            else:
                if tabulated:
                    lx, ly, lz = _profile_local(u3, u4, theta_tab, cdf)
                else:
                    lx, ly, lz = _cosine_local(u3, u4)
                dx, dy, dz = _to_world(lx, ly, lz, ax, ay, az)
                nx, ny, nz = ax, ay, az
        elif family == SPHERE:
            if tabulated and measured:
                wx, wy, wz = _measured_local(u1, u2, c_cdf, gamma_cdf, cos_edges, c_step)
            elif tabulated:
                wx, wy, wz = _profile_local(u1, u2, theta_tab, cdf)
                wy, wz = -wy, -wz  # about the light's -Z
            else:
                ct = 1.0 - 2.0 * u1
                st = math.sqrt(max(0.0, 1.0 - ct * ct))
                c, s = _turn(u2)
                wx, wy, wz = st * c, st * s, ct
            dx, dy, dz = _unit(*_apply9(lin9, wx, wy, wz))
            if point:
                x, y, z = 0.0, 0.0, 0.0
                nx, ny, nz = dx, dy, dz
            else:
                lx, ly, lz = _cosine_local(u3, u4)
                x, y, z = _to_world(lx, ly, lz, wx, wy, wz)
                x, y, z = sz[0] * x, sz[0] * y, sz[0] * z
                nx, ny, nz = _unit(*_apply9(nmap9, x, y, z))
        elif family == MESH:
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
            nx, ny, nz = _apply9(nmap9, side * mesh_normals[t, 0], side * mesh_normals[t, 1],
                                side * mesh_normals[t, 2])
            nx, ny, nz = _unit(nx, ny, nz)
            lx, ly, lz = _cosine_local(u3, u4)
            dx, dy, dz = _to_world(lx, ly, lz, nx, ny, nz)
        elif family == RAYS:
            m = ray_cdf.shape[0] - 1
            t = min(max(np.searchsorted(ray_cdf, u1, side="right") - 1, 0), m - 1)
            x, y, z = ray_pos[t, 0], ray_pos[t, 1], ray_pos[t, 2]
            dx, dy, dz = _unit(*_apply9(lin9, ray_dir[t, 0], ray_dir[t, 1], ray_dir[t, 2]))
            nx, ny, nz = dx, dy, dz  # offset along the ray
        else:  # CYLINDER: its side, not its caps
            c, s = _turn(u2)
            x, y, z = (u1 - 0.5) * sz[3], sz[0] * c, sz[0] * s
            nx, ny, nz = _unit(*_apply9(nmap9, 0.0, c, s))
            lx, ly, lz = _cosine_local(u3, u4)
            dx, dy, dz = _to_world(lx, ly, lz, nx, ny, nz)
        wx, wy, wz = _apply9(lin9, x, y, z)
        p[0, i], p[1, i], p[2, i] = wx + off3[0], wy + off3[1], wz + off3[2]
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
