"""The batch job record: which photons to trace, small enough to hash, pickle and log.

A batch is a pure function of (scene, job): photon ``i`` of emitter ``emitter`` depends on
nothing but the scene, ``seed`` and ``i``, so a job runs the same on any thread, process
or machine, and an edit can retrace exactly the jobs (or photons) it affects.
"""
from __future__ import annotations

from dataclasses import dataclass

#: Default maximum number of surface interactions; photons still alive then are cut.
MAX_DEPTH = 512


@dataclass(frozen=True)
class BatchJob:
    """Photons ``first .. first + count - 1`` of emitter number ``emitter`` (its index in
    ``Scene.emitters``), traced with ``seed`` into a cube map of ``resolution`` texels per
    face edge, cut after ``max_depth`` surface interactions."""

    emitter: int
    first: int
    count: int
    seed: int
    resolution: int
    max_depth: int = MAX_DEPTH

    @property
    def stop(self) -> int:
        """One past the last photon index of the job."""
        return self.first + self.count
