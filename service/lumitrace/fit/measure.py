"""Tracing one candidate for its merit: the same photons for every candidate.

Every candidate of a fit is traced with the fit's seed, in one pinned tracing frame, with
the same photons per emitter (shared by the first scene's fluxes; a candidate that
changes a light's flux has its photons carry the new flux): photon *i* of a candidate
leaves its emitter as photon *i* of every other candidate, so the noise of neighbours is
largely the same and cancels in their comparison (common random numbers).

A candidate that changes few photons' paths is traced selectively (threads only): the
base's counts, those photons' contributions taken out and traced again (see
:mod:`lumitrace.run.incremental`). Its counts equal a fresh trace's in the same frame,
count for count, so a merit does not depend on how it was traced, nor where.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..film.accumulate import Accumulator
from ..photometry.distribution import photometry_of
from ..photometry.measured import measure_all
from ..run.incremental import select, tally_of
from ..scene import Scene
from ..trace import rng
from ..trace.allocation import MIN_EMITTER_PHOTONS, allocate
from ..trace.job import MAX_DEPTH, BatchJob
from ..trace.prepared import TracingFrame, prepare
from ..trace.records import PhotonRecords
from ..trace.tracer import trace_batch
from .objective import C_STEP, Measurement, Needs

#: Cube-map resolution of a candidate's counts (the merit reads the goniophotometer's
#: cells, not the map: a small map costs nothing).
RESOLUTION = 8
#: Photons per batch of a candidate's trace.
BATCH = 1 << 16
#: A candidate is traced selectively when the photons its edit can change are at most
#: this share of its photons (beyond it, tracing them by index, taking their old counts
#: out and copying the base's counts cost more than a fresh trace).
SELECTIVE_SHARE = 0.6


@dataclass(frozen=True)
class Plan:
    """How every candidate of a fit is traced: ``seed``, the pinned ``frame``, and the
    emitters (paths) whose photons are shared by ``fluxes`` (the first scene's)."""

    seed: int
    frame: TracingFrame
    paths: tuple[str, ...]
    fluxes: tuple[float, ...]
    max_depth: int = MAX_DEPTH

    @classmethod
    def of(cls, scene: Scene, seed: int, max_depth: int = MAX_DEPTH) -> "Plan":
        return cls(seed, TracingFrame.of(scene), tuple(e.path for e in scene.emitters),
                   tuple(e.flux for e in scene.emitters), max_depth)

    def allocation(self, scene: Scene, photons: int) -> list[int]:
        """Photons per emitter of ``scene``: the first scene's share where it has the same
        emitters, else by its own fluxes."""
        same = tuple(e.path for e in scene.emitters) == self.paths
        fluxes = list(self.fluxes) if same else [e.flux for e in scene.emitters]
        return allocate(fluxes, max(photons, MIN_EMITTER_PHOTONS * len(fluxes)),
                        MIN_EMITTER_PHOTONS)

    def jobs(self, scene: Scene, photons: int) -> list[BatchJob]:
        out = []
        for e, n in enumerate(self.allocation(scene, photons)):
            for first in range(0, n, BATCH):
                out.append(BatchJob(e, first, min(BATCH, n - first), self.seed, RESOLUTION,
                                    self.max_depth))
        return out


def trace_counts(scene: Scene, plan: Plan, photons: int, ps=None, records: bool = False
                 ) -> tuple[Accumulator, list[PhotonRecords] | None]:
    """A fresh trace of ``scene`` in the plan's frame, on this thread: its counts, and its
    photons' records (for selective retracing) where asked."""
    plan.frame.check_fits(scene)
    ps = ps or prepare(scene, plan.frame)
    acc = Accumulator(scene, RESOLUTION, ps.goniometer)
    recs = [PhotonRecords.empty() for _ in scene.emitters] if records else None
    for job in plan.jobs(scene, photons):
        tally = trace_batch(ps, job, records=records)
        acc.add(tally)
        if records:
            recs[job.emitter] = recs[job.emitter].extend(tally.records)
    return acc, recs


@dataclass
class Base:
    """A traced scene with its photons' records, that candidates are retraced from."""

    scene: Scene
    photons: int
    accumulator: Accumulator
    records: list[PhotonRecords]


def make_base(scene: Scene, plan: Plan, photons: int) -> Base:
    acc, recs = trace_counts(scene, plan, photons, records=True)
    return Base(scene, photons, acc, recs)


def _with_fluxes(scene: Scene, fluxes) -> Scene:
    """``scene`` with its emitters' fluxes set to ``fluxes`` (a flux edit is a rescale)."""
    return dataclasses.replace(scene, emitters=tuple(
        dataclasses.replace(e, flux=f) for e, f in zip(scene.emitters, fluxes)))


def retrace_counts(base: Base, scene: Scene, plan: Plan) -> tuple[Accumulator, int] | None:
    """The counts of ``scene`` from the base's, the photons its edit can change traced
    again (with how many), or None where a fresh trace is cheaper or needed (emitters
    added or removed, geometry leaving the frame's grid, too many photons changed)."""
    if tuple(e.path for e in scene.emitters) != tuple(e.path for e in base.scene.emitters):
        return None
    fluxes = [e.flux for e in base.scene.emitters]
    edited = _with_fluxes(scene, fluxes)  # the flux edits are rescales, made after
    sel = select(base.records, base.scene, edited, plan.frame)
    if sel.restart is not None or sel.photons > SELECTIVE_SHARE * base.accumulator.photons:
        return None
    acc = base.accumulator.snapshot()
    if sel.photons:
        ps = prepare(edited, plan.frame)
        for e, rows in enumerate(sel.rows):
            if not len(rows):
                continue
            key = rng.stream_key(plan.seed, base.scene.emitters[e].key)
            acc.remove(tally_of(e, key, rows, base.records[e].take(rows), RESOLUTION))
            for k in range(0, len(rows), BATCH):
                ids = rows[k:k + BATCH]
                acc.add(trace_batch(ps, BatchJob(e, int(ids[0]), len(ids), plan.seed,
                                                 RESOLUTION, plan.max_depth), photons=ids))
    for i, e in enumerate(scene.emitters):
        acc.emitters[i].path = e.path
        if e.flux != fluxes[i]:
            acc.rescale(i, e.flux)
    return acc, sel.photons


def measurement(scene: Scene, acc: Accumulator, needs: Needs) -> Measurement:
    """What the merit needs from a candidate's counts (see :class:`Needs`)."""
    cd = sigma = halves = None
    if needs.symmetry is not None:
        grids = measure_all(acc, np.asarray(needs.gammas), C_STEP, (needs.symmetry,))
        cut = slice(None, -1) if needs.symmetry == "none" else slice(None)  # 360 repeats 0
        cd, sigma, halves = None, None, []
        for h in (None, 0, 1):
            g = grids[needs.symmetry, h]
            if h is None:
                cd, sigma = g.candela[cut], g.sigma[cut]
            else:
                halves.append((g.candela[cut], g.sigma[cut]))
    figures = {}
    if needs.figures:
        ph = photometry_of(scene, acc)
        values = ph.figures.as_dict()
        if needs.tables:
            from ..photometry.tables import application_figures

            values.update(application_figures(ph, acc))
        figures = {n: (values.get(n), values.get(f"{n}_error")) for n in needs.figures}
    fluxes = acc.fluxes()
    return Measurement(cd, sigma, figures, int(acc.photons), float(fluxes["escaped"]),
                       tuple(halves) if halves else None)


def measure_fresh(scene: Scene, plan: Plan, photons: int, needs: Needs) -> Measurement:
    """A candidate traced afresh and measured: what a worker process or a Dask worker
    runs (every argument pickles)."""
    acc, _ = trace_counts(scene, plan, photons)
    return measurement(scene, acc, needs)
