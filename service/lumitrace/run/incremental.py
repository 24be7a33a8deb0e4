"""Retracing only what an edit changes, exactly.

Photon i's path is a pure function of (scene, seed, i), and the tracing frame is pinned for
a session, so a photon whose path cannot meet anything the edit changed comes out the same
if retraced. :func:`select` finds a superset of the photons an edit can change from their
records (:mod:`lumitrace.trace.records`):

- every photon of an emitter whose shape, shaping or placement changed;
- photons that hit a part whose material changed (a material edit, a rebinding);
- photons that hit a part whose geometry changed or that is gone, and photons whose path
  segments pass through the cells the part's new geometry occupies, and through its slabs
  along each of the three axes.

:func:`retrace` takes those photons' old contributions out of the accumulator and traces
them again with the same indices; the result equals a fresh trace of the edited scene in
the same frame, count for count. Anything else (emitters added or removed, a flux edit
together with others, geometry leaving the frame's grid, records dropped above their memory
cap) is a full restart, with the reason.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

from ..film.accumulate import counts_of
from ..film.goniometer import N_BINS, N_CELLS, escape_bins
from ..film.tally import BatchTally
from ..scene import Scene
from ..trace import rng
from ..trace.job import BatchJob
from ..trace.prepared import TracingFrame
from ..trace.records import ABSORBED, CUT, PhotonRecords, part_bits


@dataclass(frozen=True)
class Selection:
    """The photons to retrace: row indices (= photon indices) per emitter, or a restart."""

    rows: tuple[np.ndarray, ...] = ()
    restart: str | None = None

    @property
    def photons(self) -> int:
        return int(sum(len(r) for r in self.rows))


def _normalised(triangles: np.ndarray, frame: TracingFrame) -> np.ndarray:
    return (np.asarray(triangles, np.float64) - np.array(frame.center)) / frame.scale


def select(records: list[PhotonRecords] | None, old: Scene, new: Scene,
           frame: TracingFrame) -> Selection:
    """The photons of ``old``'s session that the edit to ``new`` can change."""
    if records is None:
        return Selection(restart="no photon records (above their memory cap)")
    if (old.up_axis, old.meters_per_unit) != (new.up_axis, new.meters_per_unit):
        return Selection(restart="the stage's units or axes changed")
    if not np.array_equal(old.photometric_axes, new.photometric_axes):
        return Selection(restart="the luminaire turned: its photometric frame changed")
    if [e.path for e in old.emitters] != [e.path for e in new.emitters]:
        return Selection(restart="emitters were added or removed")
    if (old.colour == "spectral") != (new.colour == "spectral"):
        return Selection(restart="a surface's colour changed whether photons carry "
                                 "wavelengths")
    changed_emitters = []
    for i, (a, b) in enumerate(zip(old.emitters, new.emitters)):
        if a.flux != b.flux:
            return Selection(restart="an emitter's flux changed along with other edits")
        # where no surface has a colour, a light's spectrum changes no photon's path
        if not a.same_as(b, ignore=("spectrum",) if new.colour != "spectral" else ()):
            changed_emitters.append(i)
    new_tri = _normalised(new.triangles, frame)
    if not frame.grid.inside(new_tri):
        return Selection(restart="geometry moved outside the session's tracing frame")
    old_parts, new_parts = old.part_geometry(), new.part_geometry()
    old_mats = {m.path: m for m in old.materials}
    new_mats = {m.path: m for m in new.materials}
    changed_mats = {p for p in set(old_mats) | set(new_mats) if old_mats.get(p) != new_mats.get(p)}
    bits_of: list[str] = []
    places = []  # (cells, slabs (3,)) of every part's new geometry
    for name in set(old_parts) | set(new_parts):
        a, b = old_parts.get(name), new_parts.get(name)
        if a is None or b is None or not np.array_equal(a[0], b[0]):
            bits_of.append(name)  # moved, reshaped, added or removed
            if b is not None:
                tri = _normalised(b[0], frame)
                places.append((frame.grid.triangle_cells(tri), frame.grid.triangle_slabs(tri)))
        elif not np.array_equal(a[1], b[1]) or changed_mats & (set(a[1]) | set(b[1])):
            bits_of.append(name)  # other material slots, or a material it uses changed
    bits = np.bitwise_or.reduce(part_bits(bits_of)) if bits_of else np.uint64(0)
    rows = []
    for i, rec in enumerate(records):
        if i in changed_emitters:
            rows.append(np.arange(len(rec), dtype=np.int64))
        else:
            hit = (rec.parts & bits) != 0
            for cells, slabs in places:  # a path whose boxes can meet the part's boxes
                hit |= ((rec.cells & cells) != 0) & ((rec.slabs & slabs) != 0).all(axis=1)
            rows.append(np.flatnonzero(hit).astype(np.int64))
    return Selection(tuple(rows))


def tally_of(emitter: int, key: np.uint64, photons: np.ndarray, rec: PhotonRecords,
             resolution: int) -> BatchTally:
    """The tally these photons contributed, rebuilt from their records (to remove it)."""
    ntex = 6 * resolution * resolution
    esc = rec.texel >= 0
    half = (rng.photon_hash(key, photons[esc]) & np.uint64(1)).astype(np.int64)
    counts = np.bincount(rec.texel[esc].astype(np.int64) + ntex * half,
                         minlength=2 * ntex).reshape(2, ntex)
    cells = counts_of(escape_bins(rec.cell[esc].astype(np.int64),
                                  rec.exit[esc].astype(np.int64) + N_CELLS, half), N_BINS)
    xz = None
    if rec.colour:  # a spectral scene's X and Z, as the photons added them
        texels = rec.texel[esc].astype(np.int64) + ntex * half
        flat = rec.cell[esc].astype(np.int64) + N_CELLS * half
        x, z = rec.x[esc].astype(np.int64), rec.z[esc].astype(np.int64)
        xz = tuple(np.bincount(texels, weights=q, minlength=2 * ntex).round().astype(
            np.int64).reshape(2, ntex) for q in (x, z)) + (
            counts_of(flat, N_CELLS, x), counts_of(flat, N_CELLS, z))
    return BatchTally(emitter, int(photons[0]) if len(photons) else 0, int(len(photons)),
                      counts, cells, absorbed=int(np.count_nonzero(rec.texel == ABSORBED)),
                      cut=int(np.count_nonzero(rec.texel == CUT)),
                      segments=int(rec.segments.astype(np.int64).sum()), xz=xz)


@dataclass(frozen=True)
class Retraced:
    """What :func:`retrace` did: photons retraced of those traced, and the time (s)."""

    photons: int
    of: int
    seconds: float


def retrace(refinement, scene: Scene, selection: Selection,
            trace: Callable[[Iterable[tuple[BatchJob, np.ndarray]]], Iterable[BatchTally]],
            chunk: int) -> Retraced:
    """Replace the selected photons' contributions in ``refinement`` (a
    :class:`~lumitrace.run.session.Refinement` with records) by those of ``scene``.
    ``trace`` maps (job, photon indices) pairs to tallies with records, in order."""
    t0 = time.perf_counter()
    acc, s = refinement.accumulator, refinement.settings
    # a few pieces, so that every thread has work, but not small ones: a wave of photons
    # has a fixed cost per bounce
    chunk = max(1, min(chunk, max(8192, -(-selection.photons // 4))))
    work = []
    for e, rows in enumerate(selection.rows):
        if not len(rows):
            continue
        rec = refinement.records[e]
        key = rng.stream_key(s.seed, refinement.scene.emitters[e].key)
        acc.remove(tally_of(e, key, rows, rec.take(rows), s.resolution))
        for k in range(0, len(rows), chunk):
            ids = rows[k:k + chunk]
            work.append((BatchJob(e, int(ids[0]), len(ids), s.seed, s.resolution,
                                  s.max_depth), ids))
    for (job, ids), tally in zip(work, trace(work)):
        acc.add(tally)
        refinement.records[job.emitter].put(ids, tally.records)
    refinement.scene = scene
    for i, e in enumerate(scene.emitters):
        acc.emitters[i].path = e.path
    acc.colour = scene.colour
    acc.set_colours(scene)
    refinement.reestimate()
    traced = sum(len(r) for r in refinement.records)
    return Retraced(selection.photons, traced, time.perf_counter() - t0)
