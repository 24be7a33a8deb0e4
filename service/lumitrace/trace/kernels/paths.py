"""The path loop: photons followed bounce by bounce (a wave at a time from Embree's hits,
or each whole, four side by side casting their rays together through Embree's
``rtcIntersect4``), spectral throughputs carried along, escapes handed to the binning."""
from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from ...scene import DIELECTRIC, DIFFUSE, GLOSSY, MIRROR, TRANSLUCENT
from ..codes import MIXED, PRISTINE
from ..records import CUT
from .binning import _CHUNK, _bin_escapes, _grid_exit, _mark_segment
from .emission import _reaches, _started
from .jit import _ALWAYS, _INLINE, _JIT
from .maths import _ONE, _dot, _uniform_pair
from .scattering import scatter_one

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

#: Rays Embree intersects at once on a deep bounce (``rtcIntersect4``): four photons are
#: followed side by side, each lane taking the next photon when its own ends.
_LANES = 4
#: uint32 words of the buffer a packet is placed in: up to 16 to the first cache line after
#: its start, the valid mask's line (16 words, 4 used), the RTCRayHit4 (20 rows of 4 words,
#: five lines), 16 to spare.
_PACKET_WORDS = 16 + 24 * _LANES + 16
_HIT = 16  # the RTCRayHit4's first word
# its rows: org x y z, tnear, dir x y z, time, tfar, mask, id, flags, Ng x y z, u, v,
# primID, geomID, instID
_TFAR, _MASK, _U, _V, _PRIM, _GEOM, _INST = 8, 9, 15, 16, 17, 18, 19


@numba.njit(**_ALWAYS)
def _packet(buf):
    """An RTCRayHit4 in ``buf`` (:data:`_PACKET_WORDS` uint32) after its valid mask: the
    words as float32 and as uint32, the mask's address and the packet's. Embree writes
    each ray's hit there, so it has cache lines of its own: small allocations of two
    threads can sit side by side, and a shared line would move between the cores at every
    call. No ray is valid yet."""
    k = (64 - buf.ctypes.data % 64) // 4
    buf[k:k + _LANES] = 0
    a = numba.uint64(buf.ctypes.data + 4 * k)
    return buf[k:].view(np.float32), buf[k:], a, a + numba.uint64(4 * _HIT)


@numba.njit(**_ALWAYS)
def _cast(lane, f, u, ox, oy, oz, dx, dy, dz):
    """Ray ``lane`` of the packet (``f``, ``u``: its words) from (``ox``..``oz``) along
    (``dx``..``dz``), made float32, no hit yet, and marked valid. Returns 1 (a ray cast)."""
    u[lane] = 0xFFFFFFFF
    b = _HIT + lane
    f[b], f[b + 4], f[b + 8], f[b + 12] = ox, oy, oz, 0.0  # origin, tnear
    f[b + 16], f[b + 20], f[b + 24], f[b + 28] = dx, dy, dz, 0.0  # direction, time
    f[b + 4 * _TFAR] = np.inf
    u[b + 4 * _MASK], u[b + 40], u[b + 44] = 0xFFFFFFFF, 0, 0  # mask, id, flags
    u[b + 4 * _GEOM], u[b + 4 * _INST] = 0xFFFFFFFF, 0xFFFFFFFF  # no geometry, no instance
    return 1


@numba.njit(**_ALWAYS)
def _met(lane, f, u, offsets, order):
    """Ray ``lane``'s closest hit in the packet: its triangle (-1: none) and float32
    distance (inf: none). The quad's part is its geometry's ID, or in a two-level scene
    its instance's; of its two triangles, the second holds the hits whose u + v pass 1
    (Embree's quad parametrisation)."""
    b = _HIT + lane
    geom = u[b + 4 * _GEOM]
    if geom == 0xFFFFFFFF:
        return np.int64(-1), np.inf
    inst = u[b + 4 * _INST]
    g = geom if inst == 0xFFFFFFFF else inst
    second = np.float64(f[b + 4 * _U]) + np.float64(f[b + 4 * _V]) > 1.0
    q = offsets[g] + u[b + 4 * _PRIM]
    return np.int64(order[2 * q + second]), np.float64(f[b + 4 * _TFAR])


@numba.njit(**_ALWAYS)
def _hold(at, lane, ox, oy, oz, dx, dy, dz, qx, qy, qz):
    """Keep a lane's photon between two packets: its ray's origin and direction and its
    polarisation, row ``lane`` of ``at``."""
    at[lane, 0], at[lane, 1], at[lane, 2], at[lane, 3], at[lane, 4] = ox, oy, oz, dx, dy
    at[lane, 5], at[lane, 6], at[lane, 7], at[lane, 8] = dz, qx, qy, qz


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
    as :func:`start` moves them), :data:`_LANES` side by side, their rays cast together
    through Embree as they go (``fn``: ``rtcIntersect4``, 0: no geometry; ``scene`` ..
    ``order``: see :func:`intersect`) unless a ray misses the box ``reach_lo``..``reach_hi``,
    as :func:`cull` has it; each photon draws the numbers it draws alone, so the tallies are
    the same. Returns (survivors, escaped bins, cut, absorbed, segments).
    """
    n_out, cut, absorbed, segments = 0, 0, 0, 0
    n_parts = part_hits.shape[0]
    f, u, valid, packet = _packet(np.empty(_PACKET_WORDS, np.uint32))  # deep: Embree's rays
    staged = np.empty((6, _CHUNK))  # escapes staged for binning, and its scratch
    sbin = np.empty((2, _CHUNK), np.int64)
    binning = (staged, sbin, np.empty((3, _CHUNK)), np.empty((4, _CHUNK), np.int64))
    bins = (res, layout, counts, axes, extra_edges, 1.0 / c_step, 1.0 / g_step, n_c,
            n_gamma, lo, hi, side, n_bins, escaped, spectral, escaped_xz, xz, records,
            rec_texel, rec_cell, rec_exit, exits, exit_pos, exit_dir)
    ns = 0
    # a wave's photons go through one lane in turn; whole paths through four, each lane
    # taking the next photon when its own ends
    lanes = _LANES if deep else 1
    lane = np.full(_LANES, -1, np.int64)  # the photon in each lane (-1: none)
    at = np.empty((_LANES, 9))  # its ray's origin, direction, and its polarisation
    steps = np.empty(_LANES, np.int64)  # its bounces
    hit = np.empty(_LANES, np.int64)  # its ray's triangle (-1: none)
    hit_t = np.empty(_LANES)  # and float32 distance
    nxt, cast = 0, 0
    while True:
        busy = 0
        for k in range(lanes):
            if lane[k] < 0 and nxt < prim.shape[0]:
                i = nxt
                nxt += 1
                lane[k], steps[k], hit[k], hit_t[k] = i, depth, -1, np.inf
                if deep:  # emitted: unpolarised, in row i
                    ox, oy, oz = _started(o, pol, i, center, scale, epsilon)
                    dx, dy, dz = d[0, i], d[1, i], d[2, i]
                    qx, qy, qz = math.nan, (math.nan if polarised else 0.0), \
                        (math.nan if polarised else 0.0)
                    if fn != 0 and _reaches((ox, oy, oz), (dx, dy, dz), reach_lo, reach_hi):
                        cast += _cast(k, f, u, ox, oy, oz, dx, dy, dz)
                else:
                    ox, oy, oz = o[i, 0], o[i, 1], o[i, 2]
                    dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
                    qx = pol[i, 0] if polarised else math.nan
                    qy = pol[i, 1] if polarised else 0.0
                    qz = pol[i, 2] if polarised else 0.0
                    hit[k], hit_t[k] = prim[i], tfar[i]
                _hold(at, k, ox, oy, oz, dx, dy, dz, qx, qy, qz)
            busy += lane[k] >= 0
        if busy == 0:
            break
        if cast:
            _call_void4(fn, valid, scene, packet, numba.uint64(0))
            for k in range(lanes):
                if u[k]:
                    hit[k], hit_t[k] = _met(k, f, u, offsets, order)
                    u[k] = 0
            cast = 0
        for k in range(lanes):
            i = lane[k]
            if i < 0:
                continue
            row, j = (i, i) if deep else (pid[i], n_out)  # (j: a survivor's throughput row)
            h, step, tri, t32 = base[i], steps[k], hit[k], hit_t[k]
            ox, oy, oz, dx, dy, dz = at[k, 0], at[k, 1], at[k, 2], at[k, 3], at[k, 4], at[k, 5]
            qx, qy, qz = at[k, 6], at[k, 7], at[k, 8]
            lane[k] = -1  # unless it goes on
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
                continue
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
                continue
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
                continue
            side_sign = _dot(dx, dy, dz, nx, ny, nz)
            off = epsilon if side_sign > 0.0 else (-epsilon if side_sign < 0.0 else 0.0)
            px, py, pz = px + off * nx, py + off * ny, pz + off * nz
            if deep:  # on, from here
                lane[k], steps[k] = i, step + 1
                _hold(at, k, px, py, pz, dx, dy, dz, qx, qy, qz)
                cast += _cast(k, f, u, px, py, pz, dx, dy, dz)
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
    if ns:
        n_escaped = _bin_escapes(ns, *binning, n_escaped, *bins)
    return n_out, n_escaped, cut, absorbed, segments


@intrinsic
def _call_void4(typingctx, fn, a, b, c, e):
    """Call the C function at address ``fn`` with four pointer arguments (addresses), no
    result: Embree's ``rtcIntersect4(valid, scene, rayhit4, args)``, whose address is known
    only at run time."""
    def codegen(context, builder, signature, args):
        ptr = ir.IntType(8).as_pointer()
        f = builder.inttoptr(args[0], ir.FunctionType(ir.VoidType(), [ptr] * 4).as_pointer())
        builder.call(f, [builder.inttoptr(a, ptr) for a in args[1:]])
        return context.get_dummy_value()
    return types.void(*[types.uint64] * 5), codegen


@numba.njit(**_JIT)
def intersect(fn, scene, o32, d32, offsets, order, prim, tfar):
    """Embree's closest hit of every float32 ray ``o32``, ``d32`` (N, 3) in ``scene`` (one
    geometry of quads, or one instance of a scene of it, per part; quad j of part g holds
    triangles ``order[2 (offsets[g] + j)]`` and ``order[2 (offsets[g] + j) + 1]``):
    triangle ``prim`` (-1: none) and distance ``tfar`` (inf: none). ``fn``:
    ``rtcIntersect4``, :data:`_LANES` rays a call."""
    f, u, valid, packet = _packet(np.empty(_PACKET_WORDS, np.uint32))
    n = o32.shape[0]
    for s in range(0, n, _LANES):
        m = min(_LANES, n - s)
        for k in range(_LANES):
            u[k] = 0
            if k < m:
                _cast(k, f, u, o32[s + k, 0], o32[s + k, 1], o32[s + k, 2], d32[s + k, 0],
                      d32[s + k, 1], d32[s + k, 2])
        _call_void4(fn, valid, scene, packet, numba.uint64(0))
        for k in range(m):
            prim[s + k], tfar[s + k] = _met(k, f, u, offsets, order)


@numba.njit(**_JIT)
def pair_quads(bits, tri):
    """Triangles ``tri`` (t, 3, 3) float32 (``bits``: the same as uint32) as Embree quads:
    their corners (q, 4, 3) and the two triangles each holds (q, 2), in the triangles'
    order. Triangle i and i + 1 that share exactly one edge (two corners of the same bits)
    are quad (x, s, y, r), unless i is paired already: x the corner of i off the edge, s
    and r its others in i's own turn, y the corner of i + 1 off it, so that Embree's two
    triangles of it, (x, s, r) and (y, r, s), are i and i + 1. Any other triangle is the
    quad (a, b, c, c), whose second triangle has no area."""
    t = tri.shape[0]
    corners = np.empty((t, 4, 3), np.float32)
    held = np.empty((t, 2), np.int64)
    q, i = 0, 0
    while i < t:
        n, in_a, in_b = 0, 0, 0  # corners shared; which of i's, which of i + 1's
        if i + 1 < t:
            for j in range(3):
                for k in range(3):
                    if bits[i, j, 0] == bits[i + 1, k, 0] and \
                            bits[i, j, 1] == bits[i + 1, k, 1] and \
                            bits[i, j, 2] == bits[i + 1, k, 2]:
                        n += 1
                        in_a |= 1 << j
                        in_b |= 1 << k
        if n == 2 and in_a in (3, 5, 6) and in_b in (3, 5, 6):
            x = 0 if in_a == 6 else (1 if in_a == 5 else 2)
            y = 0 if in_b == 6 else (1 if in_b == 5 else 2)
            for c in range(3):
                corners[q, 0, c] = tri[i, x, c]
                corners[q, 1, c] = tri[i, (x + 1) % 3, c]
                corners[q, 2, c] = tri[i + 1, y, c]
                corners[q, 3, c] = tri[i, (x + 2) % 3, c]
            held[q, 0], held[q, 1] = i, i + 1
            i += 2
        else:
            for c in range(3):
                corners[q, 0, c], corners[q, 1, c] = tri[i, 0, c], tri[i, 1, c]
                corners[q, 2, c], corners[q, 3, c] = tri[i, 2, c], tri[i, 2, c]
            held[q, 0], held[q, 1] = i, i
            i += 1
        q += 1
    return corners[:q], held[:q]
