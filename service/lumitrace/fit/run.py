"""A whole fit: its inputs checked, the search, the best confirmed and written.

Everything a user can get wrong (the stage, a parameter, the target, a term, the output
folder, the scheduler) is checked before the first photon is traced, each a
:class:`~.parameters.FitError` naming it. The search's candidates share one seed; the best
is then traced again, with the next seed (its merit is not the one the search picked it
on, which is biased low by the picking), to the stated files' error, and written: its
edits layer ``NAME.lumitrace-fit.usda``, its photometric files, pictures and datasheet (as
``trace --out`` writes them, never sublayered), ``fit.json`` and ``fit.html``.
"""
from __future__ import annotations

import hashlib
import json
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import Interrupted, StageError
from ..schema import PROFILE_POINTS
from ..filenames import stage_name
from ..run.settings import TraceSettings, default_threads
from .candidates import CandidateStage
from .journal import Journal
from .measure import Plan, measurement
from .objective import Objective, parse_terms
from .parameters import FitError, Parameter, resolve
from .pool import Evaluator
from .search import Search, SearchSettings, moved
from .target import read_target


@dataclass(frozen=True)
class FitOptions:
    """What ``lumitrace fit`` was asked (see its ``--help``)."""

    stage: Path
    vary: list[str]
    target: Path | None = None
    objectives: list[str] | None = None
    constraints: list[str] | None = None
    absolute: bool = False
    symmetry: str | None = None
    photons: int = 1 << 16
    max_photons: int | None = None
    evaluations: int | None = None
    seconds: float | None = None
    final_error: float = 0.02
    seed: int = 0
    popsize: int | None = None
    workers: str = "threads"
    threads: int | None = None
    scheduler: str | None = None
    selective: bool = True
    fresh: bool = False
    out: Path | None = None
    luminaire: str | None = None
    pictures: bool = True
    #: an edits layer's file composed over the stage (the live view's session)
    edits: Path | None = None


def out_folder(opts: FitOptions) -> Path:
    """The fit's folder: ``--out``, else ``NAME.fit`` beside the stage."""
    if opts.out is not None:
        return Path(opts.out).absolute()
    return Path(opts.stage).absolute().with_name(f"{stage_name(opts.stage)}.fit")


def _writable(folder: Path) -> None:
    if folder.exists() and not folder.is_dir():
        raise FitError("the fit's folder is a file, not a folder", str(folder))
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise FitError(f"the fit's folder cannot be written: {exc.strerror}",
                       str(folder)) from None


def _check_changes(stage: CandidateStage, params: list[Parameter], start_hash: str) -> None:
    """Refuse a parameter whose values change nothing the tracer sees (an attribute the
    reader does not read, a prim outside the luminaire, an unused variant set), or whose
    range's ends make the stage unreadable (an index of refraction of 0)."""
    starts = [p.start for p in params]
    for i, p in enumerate(params):
        tries = [c for c in p.choices if c != p.start] if p.discrete else [p.lo, p.hi]
        changed = False
        for v in tries:
            if v == p.start:
                continue
            values = list(starts)
            values[i] = v
            try:
                scene = stage.scene(params, values)
            except StageError as exc:
                raise FitError(f"at {v:g} the stage cannot be read ({exc}): give a range "
                               "within the values it takes", f"--vary {p.name}") from None
            if scene.content_hash() != start_hash:
                changed = True
                break
        if not changed:
            raise FitError("changes nothing lumitrace traces over its range (an attribute "
                           "it does not read, or a prim outside the luminaire)",
                           f"--vary {p.name}")


def fit_key(scene_hash: str, params: list[Parameter], objective: Objective, opts: FitOptions,
            target_digest: str | None) -> str:
    """The journal's name for a fit: what its evaluations depend on."""
    spec = {"scene": scene_hash, "params": [p.as_dict() for p in params],
            "target": target_digest, "absolute": opts.absolute,
            "symmetry": objective.symmetry,
            "terms": [t.text for t in objective.terms + objective.constraints],
            "seed": opts.seed, "photons": opts.photons, "max_photons": opts.max_photons,
            "popsize": opts.popsize}
    return hashlib.sha256(json.dumps(spec, sort_keys=True, default=str).encode()
                          ).hexdigest()[:16]


def run_fit(opts: FitOptions, say: Callable[[str], None] | None = None,
            progress: bool = False, watch: Callable | None = None,
            should_stop: Callable[[], bool] | None = None) -> dict:
    """Run the fit ``opts`` asks for; returns its summary (the ``--json`` object).
    ``watch`` and ``should_stop``: see :class:`~.search.Search`."""
    say = say or (lambda _s: None)
    if not 0 <= opts.seed <= 2 ** 31 - 2:
        raise FitError(f"must be between 0 and {2 ** 31 - 2}, got {opts.seed}", "--seed")
    max_photons = opts.max_photons or 16 * opts.photons
    if max_photons < opts.photons:
        raise FitError(f"must be at least --photons ({opts.photons:,}), got "
                       f"{max_photons:,}", "--max-photons")
    target = read_target(opts.target) if opts.target is not None else None
    objective = Objective(target, parse_terms(opts.objectives, False),
                          parse_terms(opts.constraints, True), opts.absolute, opts.symmetry)
    if opts.scheduler is not None and opts.workers != "threads":
        raise FitError("give --scheduler or --workers processes, not both", "--scheduler")
    folder = out_folder(opts)
    stage = CandidateStage(opts.stage, opts.luminaire, opts.edits)
    params = resolve(stage.stage, opts.vary)
    starts = [p.start for p in params]
    scene0 = stage.scene(params, starts)
    start_hash = scene0.content_hash()
    _check_changes(stage, params, start_hash)
    _writable(folder)
    threads = opts.threads or default_threads()
    mode = "dask" if opts.scheduler else opts.workers
    digest = None
    if target is not None:
        digest = hashlib.sha256(Path(target.path).read_bytes()).hexdigest()
    key = fit_key(start_hash, params, objective, opts, digest)
    plan = Plan.of(scene0, opts.seed)
    for w in scene0.warnings:
        say(f"warning: {w}")
    evaluator = Evaluator(plan, objective.needs, mode, threads, opts.scheduler,
                          selective=opts.selective)
    evaluator.use_base(scene0)
    budget = opts.evaluations if opts.evaluations is not None or opts.seconds is not None \
        else 120
    settings = SearchSettings(opts.photons, max_photons, budget, opts.seconds, opts.seed,
                              opts.popsize)
    say(f"fitting {len(params)} parameter(s) of {opts.stage} "
        f"({', '.join(p.name for p in params[:4])}{' ...' if len(params) > 4 else ''}); "
        f"{mode} x {evaluator.workers}; journal {folder / 'fit.journal'}")
    bar, update = _progress(budget, opts.seconds, progress)
    journal = Journal(folder, key)
    try:
        search = Search(params, objective, stage, evaluator, settings, journal, update,
                        watch, should_stop)
        result = search.run(fresh=opts.fresh)
    except Interrupted as exc:
        exc.fit_journal = journal.path
        raise
    finally:
        if bar is not None:
            bar.close()
        evaluator.close()
    if result.resumed_from:
        say(f"resumed from the journal after generation {result.resumed_from}")
    best = result.best
    say(f"search: {len(result.evaluations)} evaluations, {result.stopped}; best merit "
        f"{best.merit:.4g} +- {best.merit_error:.2g} at {best.photons:,} photons; "
        f"confirming it (seed {opts.seed + 1}, files' error {opts.final_error:.1%})")
    try:
        return _finish(opts, stage, params, objective, target, result, folder, threads,
                       time.perf_counter(), time.process_time())
    except Interrupted as exc:
        exc.fit_journal = journal.path
        raise


def _finish(opts: FitOptions, stage: CandidateStage, params: list[Parameter],
            objective: Objective, target, result, folder: Path, threads: int,
            t_end: float, c_end: float) -> dict:
    """Confirm and write the best; ``t_end``, ``c_end``: the clocks when the search
    ended (the seconds and CPU seconds reported are the search's, its journal's earlier
    runs included, and this confirmation's)."""
    from ..publish.outputs import write_outputs
    from ..run.session import run as trace

    best = result.best
    scene = stage.scene(params, best.values)
    settings = TraceSettings(target_error=opts.final_error, seed=opts.seed + 1,
                             threads=threads, scheduler=opts.scheduler)
    traced = trace(scene, settings)
    m = objective.merit(measurement(scene, traced.accumulator, objective.needs))
    record = write_outputs(traced, folder, sublayer=False, pictures=opts.pictures,
                           deliverables=opts.pictures)
    info = {}
    for p, v in zip(params, best.values):
        info[p.name] = {**p.as_dict(), "best": v, "moved": moved(p, p.start, v),
                        "at_edge": p.at_edge(v)}
    summary = {
        "command": "fit",
        "stage": str(opts.stage),
        "best": {p.name: v for p, v in zip(params, best.values)},
        "merit": m.merit, "merit_error": m.error, "noise_floor": m.noise,
        "match": m.match, "match_error": m.match_error, "feasible": m.feasible,
        "terms": list(m.terms),
        "evaluations": len(result.evaluations),
        "generations": result.generations,
        "seconds": 0.0, "cpu_seconds": 0.0,
        "search_seconds": result.seconds, "search_cpu_seconds": result.cpu_seconds,
        "search_merit": best.merit, "search_merit_error": best.merit_error,
        "search_photons": best.photons, "stopped": result.stopped,
        "resumed_from": result.resumed_from,
        "final_photons": int(traced.accumulator.photons), "final_seed": opts.seed + 1,
        "final_error": opts.final_error,
        "edits": "", "report": str(folder / "fit.html"),
        "report_json": str(folder / "fit.json"),
        "parameters": info,
        "files": {k: record[k] for k in ("ies", "ldt", "photometry_data", "intensity_map",
                                          "result_layer", "polar_diagram",
                                          "photometric_solid", "datasheet_html",
                                          "datasheet_pdf") if record.get(k)},
    }
    layer = stage.save(params, best.values, folder, {
        "stage": Path(opts.stage).name, "merit": m.merit, "merit_error": m.error,
        "evaluations": len(result.evaluations), "seed": opts.seed,
        "best": {p.name: v for p, v in zip(params, best.values)}})
    summary["edits"] = str(layer)
    profiles = {}
    for path in sorted({p.path for p in params if p.profile}):
        pts = []
        for values in ([p.start for p in params], best.values):
            stage.author(params, values)
            attr = stage.stage.GetPrimAtPath(path).GetAttribute(PROFILE_POINTS)
            pts.append(np.array(attr.Get(), np.float64).tolist())
        profiles[path] = pts
    summary["seconds"] = result.seconds + (time.perf_counter() - t_end)
    summary["cpu_seconds"] = result.cpu_seconds + (time.process_time() - c_end)
    from .report import write_reports

    write_reports(folder, summary, result, params, objective, target, traced, record,
                  pictures=opts.pictures, profiles=profiles)
    summary["seconds"] = result.seconds + (time.perf_counter() - t_end)
    summary["cpu_seconds"] = result.cpu_seconds + (time.process_time() - c_end)
    return summary


def _progress(total: int | None, seconds: float | None, enabled: bool):
    """A tqdm bar on stderr counting evaluations (or seconds) with the best merit; a plain
    line per generation where stderr is not a terminal."""
    if not enabled:
        return None, None
    if not sys.stderr.isatty():
        def log(n, gen, photons, merit, error):
            print(f"generation {gen}: {n} evaluations, best merit {merit:.4g} +- "
                  f"{error:.2g}, next {photons:,} photons", file=sys.stderr, flush=True)
        return None, log
    from tqdm import tqdm

    bar = tqdm(total=total, unit="eval", file=sys.stderr, dynamic_ncols=True)

    def update(n, gen, photons, merit, error):
        bar.update(n - bar.n)
        bar.set_postfix_str(f"gen {gen}, merit {merit:.4g} +- {error:.2g}, "
                            f"{photons:.3g} ph")
    return bar, update
