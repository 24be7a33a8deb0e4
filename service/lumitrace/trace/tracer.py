"""The photon tracer: wavefront photon paths through the prepared scene with Embree.

A batch is a pure function ``(prepared scene, batch job) -> BatchTally``: photon i's path
depends on nothing but the scene, the seed and i, so batches can run on any thread or
machine and an edit can retrace exactly the photons it affects. All photons of a batch
advance one bounce at a time; Embree's ``run`` releases the GIL, so two threads tracing
two batches keep both cores busy.
"""
from __future__ import annotations

import numpy as np

from ..film.accumulate import counts_of
from ..film.cubemap import texel_index
from ..film.goniometer import N_BINS, N_CELLS, escape_bins
from ..film.tally import BatchTally
from ..scene import Emitter
from . import rng
from .emission import emit
from .job import MAX_DEPTH, BatchJob
from .prepared import PreparedScene, TracingFrame, prepare
from .records import CUT, PhotonRecords
from .sampling import dot
from .scattering import UNPOLARISED, kind_runs, scatter

__all__ = ["MAX_DEPTH", "BatchJob", "BatchTally", "PreparedScene", "TracingFrame", "prepare",
           "trace_batch"]

#: Ray origin offset off a surface, in normalised units (1 = the luminaire's half-size).
RAY_EPSILON = 1e-5
#: Hit points are taken this far (normalised units) before Embree's float32 hit distance.
RAY_BACKOFF = 0.5 * RAY_EPSILON
#: A hit closer to the ray's plane crossing than this (normalised units, along the normal)
#: is checked against the float64 origin: float32 rounding can put an origin that is just
#: off one face onto another one near an edge (see :func:`trace_batch`).
NEAR_HIT = 1e-6



def trace_batch(ps: PreparedScene, job: BatchJob, record_rays: bool = False,
                photons: np.ndarray | None = None, records: bool = False) -> BatchTally:
    """Trace the photons of ``job`` and tally them.

    ``photons`` (indices of the job's emitter) traces those photons instead of the job's
    range: an edit retraces exactly the photons it affects. With ``records`` the tally
    carries a :class:`~lumitrace.trace.records.PhotonRecords` per photon (in ``photons``
    order). With ``record_rays`` every traced ray (float32 origins, directions) is kept, for
    the benchmark that replays the same rays through bare Embree.
    """
    e: Emitter = ps.scene.emitters[job.emitter]
    resolution, max_depth = job.resolution, job.max_depth
    key = rng.stream_key(job.seed, e.key)
    idx = (np.arange(job.first, job.stop, dtype=np.int64) if photons is None
           else np.asarray(photons, dtype=np.int64))
    base = rng.photon_hash(key, idx)
    rec = PhotonRecords.empty(idx.size) if records else None
    pid = np.arange(idx.size) if records else None
    nseg = np.zeros(idx.size, np.int64) if records else None
    p, d, n_emit = emit(e, key, idx, normals=True)
    # off the emitting surface along its normal, as off any surface: an offset along d would
    # vanish for grazing photons and start them inside a part the light lies on
    o = (p - ps.center[:, None]) / ps.scale + RAY_EPSILON * n_emit
    # polarisation matters only where a dielectric can see it; drawn at first need
    pol = np.full_like(d, UNPOLARISED) if ps.polarised else None
    ntex = 6 * resolution * resolution
    tally = BatchTally.empty(job.emitter, job.first, int(idx.size), resolution, record_rays)
    tally.part_hits = np.zeros(len(ps.scene.parts), np.int64)
    gonio, escaped = ps.goniometer, []

    for depth in range(max_depth + 1):
        if base.size == 0:
            break
        o32 = np.ascontiguousarray(o.T, dtype=np.float32)
        d32 = np.ascontiguousarray(d.T, dtype=np.float32)
        if record_rays:
            tally.rays.append((o32, d32))
        hit = ps.intersect(o32, d32)
        tally.segments += base.size
        prim = hit["primID"]
        miss = prim < 0
        if rec is not None:
            nseg[pid] += 1
        if miss.any():
            # escapes per texel, in two halves split by the photon hash's lowest bit: two
            # independent estimates of the same map, for the error estimate
            half = (np.compress(miss, base) & np.uint64(1)).astype(np.int64)
            om, dm = np.compress(miss, o, axis=1), np.compress(miss, d, axis=1)
            texel = texel_index(dm.T, resolution)
            tally.counts += np.bincount(texel + ntex * half, minlength=2 * ntex).reshape(2, ntex)
            # the goniophotometer's cell and exit bin, counted once at the end
            cell = gonio.cells(dm)
            exit_bin = gonio.exits(om * ps.scale + ps.center[:, None], dm)
            escaped.append(escape_bins(cell, exit_bin, half))
            if rec is not None:
                gone = np.compress(miss, pid)
                rec.texel[gone] = texel
                rec.cell[gone] = cell
                rec.exit[gone] = exit_bin - N_CELLS
                rec.cells[gone] |= ps.grid.segment_cells(om, ps.grid.exit_points(om, dm))
        h = np.flatnonzero(~miss)
        if h.size == 0:
            break
        if ps.part_index.size:  # hits per part: parts no photon reaches are reported
            tally.part_hits += np.bincount(np.take(ps.part_index, np.take(prim, h)),
                                           minlength=tally.part_hits.size)
        if depth == max_depth:
            tally.cut += int(h.size)
            if rec is not None:
                rec.texel[np.take(pid, h)] = CUT
            break
        prim = np.take(prim, h)
        kind = np.take(ps.triangle_kind, prim)
        runs = kind_runs(kind)
        if len(runs) > 1:  # group the wave by scattering model: slices, not gathers
            order = np.argsort(kind, kind="stable")
            h, prim = np.take(h, order), np.take(prim, order)
            runs = kind_runs(np.take(kind, order))
        base, o, d = np.take(base, h), np.take(o, h, axis=1), np.take(d, h, axis=1)
        if pol is not None:
            pol = np.take(pol, h, axis=1)
        if rec is not None:
            pid = np.take(pid, h)
        # Embree's float32 tfar puts the hit point up to a few ulps beyond the surface, along
        # the ray; near an edge that can be behind the adjoining face, and the normal offset
        # below does not undo it (light leaked out of closed boxes at their edges). Backing
        # up along the ray, by more than that error but never beyond the origin, keeps the
        # point in the space the ray crossed.
        t = np.take(hit["tfar"], h).astype(np.float64)
        p = o + (t - np.minimum(RAY_BACKOFF, 0.5 * t)) * d
        ng = np.take(ps.normals, prim, axis=1)
        if rec is not None:
            rec.parts[pid] |= np.take(ps.part_bits, prim)
            rec.cells[pid] |= ps.grid.segment_cells(o, p)
        # A hit at about the ray's origin, on a face the float64 origin lies in front of
        # while the ray moves away from it, is no hit: the origin was just off this face
        # (an edge or corner away from the face it left) and float32 rounding put it on
        # it. The photon goes on unchanged (escaped out of a corner of a closed box
        # otherwise). Only hits within float32 rounding of the origin need the test.
        cos_in = dot(d, ng)
        near = np.flatnonzero(t * np.abs(cos_in) < NEAR_HIT)
        stay = None
        if near.size:
            rel = np.take(o, near, axis=1) - np.take(ps.corners, np.take(prim, near), axis=1)
            away = dot(rel, np.take(ng, near, axis=1)) * np.take(cos_in, near) > 0.0
            if away.any():
                stay = near[away]
        rnd = rng.uniforms_from(base, (depth + 1) * rng.DIMS_PER_BOUNCE, 4)
        d_in, pol_in = d, pol
        d, alive, pol = scatter(ps.table, np.take(ps.material_index, prim), d, ng, rnd, pol, runs)
        if stay is not None:
            d[:, stay] = d_in[:, stay]
            alive[stay] = True
            if pol is not None:
                pol[:, stay] = pol_in[:, stay]
        n_alive = int(np.count_nonzero(alive))
        tally.absorbed += int(base.size - n_alive)
        if n_alive < base.size:
            base = np.compress(alive, base)
            if rec is not None:
                pid = np.compress(alive, pid)
            d, p, ng = (np.compress(alive, a, axis=1) for a in (d, p, ng))
            if pol is not None:
                pol = np.compress(alive, pol, axis=1)
        o = p + (RAY_EPSILON * np.sign(dot(d, ng))) * ng
    if escaped:
        tally.cells = counts_of(np.concatenate(escaped), N_BINS)
    if rec is not None:
        rec.segments[:] = np.minimum(nseg, np.iinfo(np.uint16).max)
        tally.records = rec
    return tally
