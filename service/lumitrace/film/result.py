"""A traced result: the accumulated photons of a session and the maps estimated from them,
the one shape the tracing session hands to the writers (neither knows the other)."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from ..scene import Scene
from .accumulate import Accumulator
from .convergence import MapEstimate, estimate


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
    #: None in a frozen copy handed to another thread to estimate (:meth:`estimated`)
    estimate: MapEstimate | None
    #: batches sent again after a Dask worker was lost (with it, their tallies or the scene)
    batches_redone: int = 0
    #: the photometric files' accuracy (a ``lumitrace.photometry.accuracy.FilesAccuracy``)
    #: where the settings judge the target on the files (set by the writer from the grid
    #: it writes where the session had none current)
    files_accuracy: Any = None
    #: whether the target is judged on the files (else on the map)
    judge_files: bool = False

    def estimated(self) -> TraceResult:
        """This result with its map estimated from its counts where that was left to
        whoever writes it (:attr:`estimate` None)."""
        if self.estimate is not None:
            return self
        return replace(self, estimate=estimate(self.accumulator, self.settings.threshold))

    @property
    def photons(self) -> int:
        return self.accumulator.photons

    @property
    def relative_error(self) -> float:
        """Estimated relative RMS error of the map written as ``Y``."""
        return self.estimate.error

    @property
    def judged_on(self) -> str:
        """What the target error is judged on: "files" or "map"."""
        return "files" if self.judge_files else "map"

    @property
    def judged_error(self) -> float:
        """The error the target is compared with: the files' (their RMS bound, or their
        worst lit value's share) or the map's error bound."""
        if self.judge_files:
            return self.files_accuracy.error if self.files_accuracy is not None else math.inf
        return self.estimate.error_bound

    @property
    def converged(self) -> bool:
        """Whether the files (RMS bound and worst lit value) or the map (its error bound,
        not its point estimate) are within the target."""
        target = self.settings.convergence_target
        if self.judge_files:
            return self.files_accuracy is not None and self.files_accuracy.meets(target)
        return self.estimate.meets(target)
