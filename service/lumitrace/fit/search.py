"""The search: CMA-ES (``cma``) over the parameters, generation by generation.

Continuous parameters are searched in [0, 1] over their ranges, discrete ones (variant
sets, whole numbers) by the index of their choice, rounded (``cma``'s integer handling
keeps its steps from shrinking below one choice). Every candidate of a generation is traced
with the same photons; the photons double for the next generation whenever the spread of
the generation's merits is less than twice the noise of comparing them
(:func:`comparison_noise`, from the photons' two halves: the differences being judged are
drowning in it), up to a most. The search ends at the evaluations or
time given, or when ``cma`` says it has converged. The best is the lowest merit measured
at the last photon count, the optimiser's mean among the candidates.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..errors import StageError
from .candidates import CandidateStage
from .journal import Journal, pack_state, unpack_state
from .objective import Merit, Objective
from .parameters import Parameter
from .pool import Evaluator

#: The optimiser's first step, as a share of each range.
SIGMA0 = 0.25
#: The photons double when a generation's merits spread less than this many times the
#: noise of their comparison (the differences being judged drown in it).
GROW_BELOW = 2.0
#: ``cma``'s step tolerance, in shares of the ranges: closer than this is converged.
TOLX = 1e-4
#: The merit of a candidate whose values make the stage unreadable (worse than any).
FAILED_MERIT = 1e3


@dataclass(frozen=True)
class SearchSettings:
    """Photons per candidate at first and at most, the stop (evaluations and/or
    seconds), the seed of every candidate's photons (the optimiser's own is derived from
    it) and the population (None: ``cma``'s default for the dimension)."""

    photons: int
    max_photons: int
    evaluations: int | None
    seconds: float | None
    seed: int
    popsize: int | None = None


@dataclass(frozen=True)
class Evaluation:
    """One traced candidate: its values (one per parameter), photons, merit and the parts
    of it, and when it was done (seconds and CPU seconds since the fit began: since
    lumitrace loaded and since the process started, of every run of a resumed fit)."""

    index: int
    generation: int
    values: tuple
    photons: int
    merit: float
    merit_error: float
    noise: float
    match: float | None
    terms: tuple
    feasible: bool
    retraced: int | None
    seconds: float
    cpu_seconds: float
    mean: bool = False  # the optimiser's mean, measured at the end
    halves: tuple | None = None  # the merit from each half of the photons

    def as_dict(self) -> dict:
        return {"index": self.index, "generation": self.generation,
                "values": list(self.values), "photons": self.photons, "merit": self.merit,
                "merit_error": self.merit_error, "noise_floor": self.noise,
                "match": self.match, "terms": list(self.terms), "feasible": self.feasible,
                "retraced": self.retraced, "seconds": self.seconds,
                "cpu_seconds": self.cpu_seconds, "mean": self.mean,
                "halves": None if self.halves is None else list(self.halves)}

    @classmethod
    def from_dict(cls, d: dict) -> "Evaluation":
        return cls(d["index"], d["generation"], tuple(d["values"]), d["photons"],
                   d["merit"], d["merit_error"], d["noise_floor"], d["match"],
                   tuple(d["terms"]), d["feasible"], d["retraced"], d["seconds"],
                   d["cpu_seconds"], d.get("mean", False),
                   None if d.get("halves") is None else tuple(d["halves"]))


@dataclass
class SearchResult:
    """The evaluations made, the best of them, why the search ended, and its time."""

    evaluations: list[Evaluation]
    best: Evaluation
    stopped: str
    seconds: float
    cpu_seconds: float
    generations: int
    resumed_from: int = 0
    #: per generation: (generation, photons, the noise of comparing its merits)
    photon_steps: list = field(default_factory=list)


def _json_value(v):
    return v if isinstance(v, str) else float(v) if not isinstance(v, (int, np.integer)) \
        else int(v)


class Search:
    """A fit's search over ``params`` of ``objective``: candidates made on ``stage``,
    traced by ``evaluator``, journalled in ``journal``; ``progress(evaluations,
    generation, photons, best merit, error)`` is told after every generation, and
    ``watch(generation's evaluations, its best's measurement)`` too; the search ends
    before a generation when ``should_stop()`` says so (the live view's Stop)."""

    def __init__(self, params: Sequence[Parameter], objective: Objective,
                 stage: CandidateStage, evaluator: Evaluator, settings: SearchSettings,
                 journal: Journal,
                 progress: Callable[[int, int, int, float, float], None] | None = None,
                 watch: Callable[[list, object], None] | None = None,
                 should_stop: Callable[[], bool] | None = None):
        self.params, self.objective, self.stage = list(params), objective, stage
        self.evaluator, self.settings, self.journal = evaluator, settings, journal
        self.progress, self.watch, self.should_stop = progress, watch, should_stop
        self._measured: dict[int, object] = {}  # the last generation's measurements

    def _options(self) -> dict:
        opts = {"seed": self.settings.seed + 1, "verbose": -9, "tolx": TOLX,
                "tolfun": 0.0, "tolflatfitness": 10_000}
        discrete = [i for i, p in enumerate(self.params) if p.discrete]
        if discrete:
            opts["integer_variables"] = discrete
            opts["CMA_stds"] = [max(1.0, len(p.choices) - 1.0) if p.discrete else 1.0
                                for p in self.params]
        if self.settings.popsize:
            opts["popsize"] = self.settings.popsize
        return opts

    def unit(self, x) -> list[float]:
        """The parameters' search coordinates of an optimiser's point: each folded into
        its bounds by reflection at them (``cma``'s own bound handling fails in one
        dimension; a reflection keeps the search's distribution whole at an edge)."""
        out = []
        for p, v in zip(self.params, x):
            lo, hi = p.unit_bounds
            t = math.fmod(abs(float(v) - lo) / (hi - lo), 2.0)
            out.append(lo + (2.0 - t if t > 1.0 else t) * (hi - lo))
        return out

    def values(self, x) -> tuple:
        """The parameters' values at an optimiser's point."""
        return tuple(_json_value(p.from_unit(v)) for p, v in zip(self.params, self.unit(x)))

    def run(self, fresh: bool = False) -> SearchResult:
        import cma

        s = self.settings
        generations = self.journal.load(fresh)
        evaluations: list[Evaluation] = []
        steps = []
        if generations:
            last = generations[-1]
            es = unpack_state(last["state"])
            photons = int(last["next_photons"])
            for g in generations:
                evaluations += [Evaluation.from_dict(e) for e in g["evaluations"]]
                steps.append((g["generation"], g["photons"], g.get("comparison_noise")))
            offset, cpu_offset = float(last["seconds"]), float(last["cpu_seconds"])
        else:
            x0 = [p.to_unit(p.start) for p in self.params]
            es = cma.CMAEvolutionStrategy(x0, SIGMA0, self._options())
            photons = s.photons
            offset = cpu_offset = 0.0
        resumed = len(generations)
        t0, c0 = time.perf_counter(), time.process_time()
        if not resumed:  # a fresh fit counts from the command's start: loading, reading
            from .. import STARTED

            t0, c0 = STARTED, 0.0
        clock = lambda: (offset + time.perf_counter() - t0,  # noqa: E731
                         cpu_offset + time.process_time() - c0)
        generation = resumed
        stopped = ""
        while True:
            if s.evaluations is not None and len(evaluations) >= s.evaluations:
                stopped = f"{len(evaluations)} evaluations"
                break
            if s.seconds is not None and clock()[0] >= s.seconds:
                stopped = f"{s.seconds:g} s"
                break
            if self.should_stop is not None and self.should_stop():
                stopped = "stopped"
                break
            done = es.stop()
            if done:
                stopped = "converged (" + ", ".join(sorted(done)) + ")"
                break
            xs = es.ask()
            batch = self._evaluate([self.values(x) for x in xs], photons, generation,
                                   len(evaluations), clock)
            es.tell(xs, [e.merit for e in batch])
            evaluations += batch
            noise = comparison_noise([e for e in batch if e.merit < FAILED_MERIT] or batch)
            steps.append((generation, photons, noise))
            next_photons = self._next_photons(batch, photons)
            seconds, cpu = clock()
            self.journal.append({"kind": "generation", "generation": generation,
                                 "photons": photons, "next_photons": next_photons,
                                 "comparison_noise": noise,
                                 "evaluations": [e.as_dict() for e in batch],
                                 "seconds": seconds, "cpu_seconds": cpu,
                                 "state": pack_state(es)})
            photons = next_photons
            generation += 1
            best = min(batch, key=lambda e: e.merit)
            if self.progress is not None:
                self.progress(len(evaluations), generation, photons, best.merit,
                              best.merit_error)
            if self.watch is not None:
                self.watch(batch, self._measured.get(best.index))
        last_photons = max((e.photons for e in evaluations), default=photons)
        mean = self.values(es.mean)
        final = [e for e in evaluations if e.photons == last_photons]
        if not any(e.values == mean for e in final):
            m = self._evaluate([mean], last_photons, generation, len(evaluations), clock,
                               mean=True)
            evaluations += m
            final += m
        best = min(final, key=lambda e: (not e.feasible, e.merit))
        seconds, cpu = clock()
        return SearchResult(evaluations, best, stopped, seconds, cpu, generation, resumed,
                            steps)

    def _next_photons(self, batch: list[Evaluation], photons: int) -> int:
        """The next generation's photons: twice these where the spread of this
        generation's merits is less than :data:`GROW_BELOW` times the noise of comparing
        them (:func:`comparison_noise`), at most the settings' most."""
        batch = [e for e in batch if e.merit < FAILED_MERIT]
        if photons >= self.settings.max_photons or len(batch) < 3:
            return photons
        spread = float(np.std([e.merit for e in batch], ddof=1))
        noisy = spread < GROW_BELOW * comparison_noise(batch)
        return min(2 * photons, self.settings.max_photons) if noisy else photons

    def _evaluate(self, values: list[tuple], photons: int, generation: int, first: int,
                  clock, mean: bool = False) -> list[Evaluation]:
        """Trace and measure candidates; one whose values make the stage unreadable (a
        StageError: what its parameters' ranges should have kept out) is not traced and
        gets :data:`FAILED_MERIT`, its reason kept, so the search goes on around it."""
        scenes, failed = [], {}
        for i, v in enumerate(values):
            try:
                scenes.append(self.stage.scene(self.params, v))
            except StageError as exc:
                failed[i] = str(exc)
        traced = iter(self.evaluator.evaluate(scenes, photons))
        seconds, cpu = clock()
        out = []
        self._measured = {}
        for i, v in enumerate(values):
            if i in failed:
                out.append(Evaluation(first + i, generation, v, photons, FAILED_MERIT, 0.0,
                                      0.0, None, ({"failed": failed[i]},), False, None,
                                      seconds, cpu, mean))
                continue
            t = next(traced)
            self._measured[first + i] = t.measurement
            m: Merit = self.objective.merit(t.measurement)
            out.append(Evaluation(first + i, generation, v, photons, m.merit, m.error,
                                  m.noise, m.match, m.terms, m.feasible, t.retraced,
                                  seconds, cpu, mean, m.halves))
        return out


def comparison_noise(batch: Sequence[Evaluation]) -> float:
    """The standard deviation of the noise in a generation's merits *relative to one
    another*, which is what ranks them: with common random numbers far below each merit's
    own standard error, since neighbours share most of their noise. Measured from the two
    independent halves of the photons (each a common-random-number experiment of its
    own): the candidates' deviations from their generation's mean in one half less those
    in the other are twice a half's noise, four times the variance of the whole's. Without
    halves (figure goals alone), the median merit standard error."""
    if len(batch) < 2 or any(e.halves is None for e in batch):
        return float(np.median([e.merit_error for e in batch]))
    a = np.array([e.halves[0] for e in batch])
    b = np.array([e.halves[1] for e in batch])
    d = (a - a.mean()) - (b - b.mean())
    return math.sqrt(float((d * d).sum()) / (len(d) - 1) / 4.0)


def moved(param: Parameter, start, best) -> float | None:
    """How far a continuous parameter moved, as a share of its range (None: discrete)."""
    if param.discrete:
        return None
    return (float(best) - float(start)) / (param.hi - param.lo)


def finite(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)
