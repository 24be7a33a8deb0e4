"""A traced result: the accumulated photons of a session and the maps estimated from them,
the one shape the tracing session hands to the writers (neither knows the other)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..scene import Scene
from .accumulate import Accumulator
from .convergence import MapEstimate


@dataclass
class TraceResult:
    """The accumulated photons of a session and the maps estimated from them."""

    scene: Scene
    #: the settings it was traced with (a ``lumitrace.run.settings.TraceSettings``:
    #: photons, seed, resolution, threshold, target error)
    settings: Any
    accumulator: Accumulator
    iterations: int
    seconds: float
    prepare_seconds: float
    estimate: MapEstimate
    #: batches traced again after a Dask worker was lost (their first tallies never came)
    batches_redone: int = 0

    @property
    def photons(self) -> int:
        return self.accumulator.photons

    @property
    def relative_error(self) -> float:
        """Estimated relative RMS error of the map written as ``Y``."""
        return self.estimate.error

    @property
    def converged(self) -> bool:
        """Whether the map's error bound (not its point estimate) is within the target."""
        return self.estimate.meets(self.settings.convergence_target)
