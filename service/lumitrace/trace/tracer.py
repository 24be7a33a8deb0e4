"""The photon tracer: wavefront photon paths through the prepared scene with Embree.

A batch is a pure function ``(prepared scene, batch job) -> BatchTally``: photon i's path
depends on nothing but the scene, the seed and i, so batches can run on any thread or
machine and an edit can retrace exactly the photons it affects. A batch's photons are
emitted and followed to their ends a chunk at a time, in one compiled call that releases
the GIL and calls Embree as it goes, so two threads tracing two batches keep both cores
busy. Where only embreex is at hand (or every ray is kept, for the benchmark) a batch
advances a bounce at a time, between embreex's batched calls; the photons and their
tallies are the same either way.
"""
from __future__ import annotations

import threading

import numpy as np

from ..film import cubemap
from ..film.accumulate import EscapeBins, counts_of
from ..film.goniometer import N_BINS, N_CELLS
from ..film.tally import BatchTally
from ..scene import Emitter
from . import compiled, rng
from .codes import PRISTINE
from .emission import emit, photon_bands
from .job import MAX_DEPTH, BatchJob
from .prepared import NO_HITS, PreparedScene, TracingFrame, prepare
from .records import PhotonRecords
from .scattering import UNPOLARISED

__all__ = ["MAX_DEPTH", "BatchJob", "BatchTally", "PreparedScene", "TracingFrame", "prepare",
           "trace_batch"]

#: Ray origin offset off a surface, in normalised units (1 = the luminaire's half-size).
RAY_EPSILON = 1e-5
#: Hit points are taken this far (normalised units) before Embree's float32 hit distance.
RAY_BACKOFF = 0.5 * RAY_EPSILON
#: A hit closer to the ray's plane crossing than this (normalised units, along the normal)
#: is checked against the float64 origin: float32 rounding can put an origin that is just
#: off one face onto another one near an edge (see :func:`~lumitrace.trace.kernels.bounce`).
NEAR_HIT = 1e-6

_local = threading.local()


class _Waves:
    """A thread's wave buffers, reused from batch to batch: freshly mapped temporaries
    cost page faults on every bounce. Two sets of (o, d, pol, hash, row), swapped each
    bounce, the float32 rays for Embree and its hits. (The escapes' bins are the batch's
    own: its tally keeps them.)"""

    def __init__(self, n: int):
        self.size = n
        self.o = [np.empty((n, 3)), np.empty((n, 3))]
        self.d = [np.empty((n, 3)), np.empty((n, 3))]
        self.pol = [np.empty((n, 3)), np.empty((n, 3))]
        self.base = [np.empty(n, np.uint64), np.empty(n, np.uint64)]
        self.pid = [np.empty(n, np.int64), np.empty(n, np.int64)]
        self.o32 = np.empty((n, 3), np.float32)
        self.d32 = np.empty((n, 3), np.float32)
        self.prim = np.empty(n, np.int32)  # Embree's hits
        self.tfar = np.empty(n, np.float32)
        self.rows = np.arange(n, dtype=np.int64)
        self.tp = self.tband = self.escaped_xz = None

    def spectral(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Room for the throughput (n, bands), the photons' states (n,) set to pristine
        (throughput 1 in every band, the rows not written) and room for the escapes' X
        and Z (2, n) of a spectral batch of ``n`` photons."""
        from ..scene.spectra import BANDS

        if self.tp is None:
            self.tp = np.empty((self.size, BANDS))
            self.tband = np.empty(self.size, np.int64)
            self.escaped_xz = np.empty((2, self.size), np.int64)
        self.tband[:n] = PRISTINE
        return self.tp, self.tband, self.escaped_xz

    @classmethod
    def at_least(cls, n: int) -> "_Waves":
        w = getattr(_local, "waves", None)
        if w is None or w.size < n:
            w = _local.waves = cls(max(n, 1024))
        return w


#: Photons emitted and followed at a time on whole paths: their start points, directions
#: and normals (72 bytes a photon) stay in the core's cache from one kernel to the next,
#: and a thread's buffers stay small whatever the batch (a batch of 2^18 photons touched
#: 19 MB of them a thread).
PATH_CHUNK = 1 << 14
_NO_RECORDS = PhotonRecords.empty(0)
_NO_XZ = np.zeros((4, 1), np.int64)
_NO_TP = np.zeros((1, 1))
_NO_BAND = np.zeros(1, np.int64)
_NO_EXITS = np.zeros((0, 3))
#: The cube map's texel layout (:mod:`lumitrace.film.cubemap`) as the kernel takes it.
_CUBE_LAYOUT = np.stack([cubemap._C0, cubemap._CX, cubemap._CY, cubemap._R0, cubemap._RX,
                         cubemap._RY])


def _own_lines(n: int) -> np.ndarray:
    """``n`` int64 zeros on cache lines no other array shares. A count the kernel adds to
    at every hit: two threads' small arrays side by side on one line made each add wait
    for the line to come back from the other core (10% more CPU time on two threads)."""
    return np.zeros(n + 16, np.int64)[8:8 + n]


def trace_batch(ps: PreparedScene, job: BatchJob, record_rays: bool = False,
                photons: np.ndarray | None = None, records: bool = False,
                exit_rays: bool = False) -> BatchTally:
    """Trace the photons of ``job`` and tally them.

    ``photons`` (indices of the job's emitter) traces those photons instead of the job's
    range: an edit retraces exactly the photons it affects. With ``records`` the tally
    carries a :class:`~lumitrace.trace.records.PhotonRecords` per photon (in ``photons``
    order). With ``record_rays`` every traced ray (float32 origins, directions) is kept, for
    the benchmark that replays the same rays through bare Embree. With ``exit_rays`` the
    tally's ``exit_rays`` holds, for every photon that escaped, where it left the
    luminaire's box (world m) and its direction, (M, 3) float64 each, in photon order.
    """
    e: Emitter = ps.scene.emitters[job.emitter]
    key = rng.stream_key(job.seed, e.key)
    idx = None if photons is None else np.asarray(photons, dtype=np.int64)
    n = job.count if idx is None else int(idx.size)

    def photons_at(s: slice) -> np.ndarray:
        """The indices of the batch's photons ``s`` (a job's range made a chunk at a time:
        not 2 MB of them a batch)."""
        if idx is not None:
            return idx[s]
        first, stop, _ = s.indices(n)
        return np.arange(job.first + first, job.first + stop, dtype=np.int64)

    tally = BatchTally.empty(job.emitter, job.first, n, job.resolution, record_rays)
    tally.part_hits = _own_lines(len(ps.scene.parts))  # added to at every hit
    if n == 0:
        return tally
    w = _Waves.at_least(n)
    escaped = np.empty(2 * n, np.int64)  # its escapes' bins: the tally's, not copied
    spectral = ps.spectral
    rec = PhotonRecords.empty(n, colour=spectral) if records else None
    exit_pos = np.full((n, 3), np.nan) if exit_rays else _NO_EXITS
    exit_dir = np.zeros((n, 3)) if exit_rays else _NO_EXITS
    r = rec if rec is not None else _NO_RECORDS
    if spectral:  # unit throughput in every band, nothing coloured met yet
        xz = np.zeros((4, tally.counts.shape[1]), np.int64)
        tp, tband, escaped_xz = w.spectral(n)
    else:
        xz, tp, tband, escaped_xz = _NO_XZ, _NO_TP, _NO_BAND, _NO_XZ

    def args(s: slice) -> tuple[tuple, tuple]:
        """The bounce kernel's arguments around the photons' own and the escapes' count,
        for the photons ``s`` of the batch: float32 rays, scene, tallies, escapes; part
        hits, goniophotometer, records, exits, offsets."""
        head = (w.o32, w.d32, *ps.kernel_args, ps.band_weights[job.emitter], tp[s], tband[s],
                xz, escaped_xz, tally.counts, job.resolution, _CUBE_LAYOUT, escaped)
        tail = (tally.part_hits, *ps.gonio_args, rec is not None, r.texel[s], r.cell[s],
                r.exit[s], r.segments[s], r.parts[s], r.cells[s], r.slabs[s], r.x[s], r.z[s],
                *ps.grid_args, exit_rays, exit_pos[s], exit_dir[s], RAY_EPSILON, RAY_BACKOFF,
                NEAR_HIT)
        return head, tail

    hit = None if record_rays else ps.hit_args
    if hit is not None:  # every path followed to its end, a chunk of photons at a time
        n_escaped = 0
        for first in range(0, n, PATH_CHUNK):
            m = min(PATH_CHUNK, n - first)
            emitted = _emitted(ps, job, e, key, photons_at(slice(first, first + m)), w, m)
            if spectral and e.ray_bands:  # its ray's band, from its hash
                tband[first:first + m] = photon_bands(e, emitted[3],
                                                      ps.emitter_args[job.emitter])
            head, tail = args(slice(first, first + m))
            _, n_escaped, cut, absorbed, segments = compiled.bounce(
                0, job.max_depth, w.prim[:m], w.tfar[:m], *emitted, *emitted, *head,
                n_escaped, *tail, True, *hit)
            tally.cut += cut
            tally.absorbed += absorbed
            tally.segments += segments
    else:  # moved into the normalised frame as the first wave
        p, d, n_emit, base, _ = _emitted(ps, job, e, key, photons_at(slice(None)), w, n)
        compiled.start(p, d, n_emit, ps.center, ps.scale, RAY_EPSILON, w.o[0], w.d[0], w.o32,
                       w.d32)
        w.pid[0][:n] = w.rows[:n]
        # polarisation matters only where a dielectric can see it
        if ps.polarised:
            w.pol[0][:n] = UNPOLARISED
        # emitted photons that cannot meet any geometry escape without Embree
        reach = compiled.cull(n, w.o[0], w.d[0], w.base[0], w.pid[0], w.o32, w.d32,
                              *ps.reach_box) if ps.embree is not None else 0
        if spectral and e.ray_bands:  # its ray's band (from its hash: wherever culling
            tband[:n] = photon_bands(e, base, ps.emitter_args[job.emitter])  # put it)
        n_escaped = _waves(ps, job, w, tally, n, reach, *args(slice(None)))
    if n_escaped:
        tally.cells = EscapeBins(N_BINS, escaped[:n_escaped])
    if spectral:
        tally.xz = _colour_tallies(xz, escaped[:n_escaped:2],
                                   escaped_xz[:, :n_escaped // 2])
    if rec is not None:
        tally.records = rec
    if exit_rays:
        out = ~np.isnan(exit_pos[:, 0])
        tally.exit_rays = (exit_pos[out], exit_dir[out])
    return tally


def _emitted(ps: PreparedScene, job: BatchJob, e: Emitter, key, idx: np.ndarray, w: _Waves,
             m: int) -> tuple:
    """Photons ``idx`` (``m`` of them) emitted into the second set of buffers (free until
    the first bounce): their start points, directions, surface normals (3, m; world),
    hashes (m,), and the rows' buffer, as the bounce kernel takes them."""
    p, d, n_emit = emit(e, key, idx, normals=True,
                        out=tuple(a.reshape(-1)[:3 * m].reshape(3, m)
                                  for a in (w.o[1], w.d[1], w.pol[1])) + (w.base[0][:m],),
                        args=ps.emitter_args[job.emitter])
    return p, d, n_emit, w.base[0][:m], w.pid[0]


def _state(w: _Waves, s: int, n: int) -> tuple:
    """Buffer set ``s`` of the waves, as a bounce reads or writes it."""
    return w.o[s], w.d[s], w.pol[s], w.base[s][:n], w.pid[s]


def _waves(ps: PreparedScene, job: BatchJob, w: _Waves, tally: BatchTally, n: int, reach: int,
           head: tuple, tail: tuple) -> int:
    """Trace a batch a bounce at a time: Embree's batches between compiled bounces (for
    embreex, and to keep every ray cast); returns the escaped bins written."""
    n_escaped, cur = 0, 0
    for depth in range(job.max_depth + 1):
        o32, d32 = w.o32[:reach], w.d32[:reach]
        if tally.rays is not None:
            tally.rays.append((o32.copy(), d32.copy()))
        if reach:
            hit = ps.intersect(o32, d32, w.prim, w.tfar)
            prim, tfar = hit["primID"], hit["tfar"]
        if reach < n:
            prim = np.concatenate([prim, np.full(n - reach, -1, np.int32)]) if reach \
                else np.full(n, -1, np.int32)
            tfar = np.concatenate([tfar, np.full(n - reach, np.inf, np.float32)]) if reach \
                else np.full(n, np.inf, np.float32)
        nxt = 1 - cur
        n_next, n_escaped, cut, absorbed, segments = compiled.bounce(
            depth, job.max_depth, prim, tfar, *_state(w, cur, n), *_state(w, nxt, n), *head,
            n_escaped, *tail, False, *NO_HITS)
        tally.segments += segments
        tally.cut += cut
        tally.absorbed += absorbed
        cur, n = nxt, n_next
        reach = n  # rays that leave a surface start within the geometry's bounds
        if n == 0:
            break
    return n_escaped


def _colour_tallies(xz: np.ndarray, cells: np.ndarray, escaped_xz: np.ndarray) -> tuple:
    """A batch's X and Z tallies: the texels' (filled by the kernel) and the C-gamma
    cells' (from the escapes' cells, halves folded in as + N_BINS, and X and Z)."""
    half, cell = np.divmod(cells, N_BINS)
    flat = cell + N_CELLS * half
    return (xz[:2], xz[2:], counts_of(flat, N_CELLS, escaped_xz[0]),
            counts_of(flat, N_CELLS, escaped_xz[1]))
