"""A fit started from the live view: ``lumitrace fit`` over the live stage (the stage with
the session's edits layer as it was at the start), run in a process of its own so that
the service's USD and its tracing are untouched by it, its progress published as ``fit``
events, its best applied as one delta when the designer asks.

One fit at a time. The target is a photometric file the page uploads (IES or EULUMDAT
text), or a kept revision's preview (:func:`revision_target`); the parameters are spelled
as ``lumitrace fit --vary`` spells them. The fit writes its folder (``fit.json``, its
files, ``NAME.lumitrace-fit.usda``) as ``fit-N`` in the service's output folder's
``fit/``; the stage and the edits layer are never written by it: the best reaches the
session only when the page applies it (``POST /fit/apply``), as one ``layer`` delta.
"""
from __future__ import annotations

import math
import multiprocessing
import os
import queue
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..delta.protocol import DeltaError, Problem

#: What a page may ask of one fit: evaluations at most, photons per evaluation at most.
MOST_EVALUATIONS = 2000
MOST_PHOTONS = 1 << 22
#: The defaults: a first look in about a minute for a demo-sized luminaire.
EVALUATIONS = 40
PHOTONS = 1 << 14
#: Largest target file accepted (characters).
MAX_TARGET_CHARS = 4 << 20
#: The planes (C, deg) whose curves the page draws, each with its opposite.
CURVE_PLANES = (0.0, 90.0)
#: Seconds a fit's process is given to end after Stop when the service stops.
END_WAIT = 10.0


def _bad(where: str, why: str) -> DeltaError:
    return DeltaError([Problem(where, why)], 422)


@dataclass(frozen=True)
class FitRequest:
    """A fit the page asked for: the target file's name and text, the parameters
    (``--vary`` spellings), evaluations, photons per evaluation, and the seed."""

    target_name: str
    target_text: str
    vary: tuple[str, ...]
    evaluations: int = EVALUATIONS
    photons: int = PHOTONS
    seed: int = 0
    final_error: float = 0.05

    @classmethod
    def of(cls, body: dict) -> "FitRequest":
        """The request in a POST /fit body, or a :class:`DeltaError` naming what is wrong."""
        target = body.get("target")
        if not isinstance(target, dict) or not isinstance(target.get("text"), str):
            raise _bad("/target", 'give the target file as {"name": NAME, "text": ITS TEXT}')
        name = target.get("name", "target.ies")
        if not isinstance(name, str) or Path(name).suffix.lower() not in (".ies", ".ldt"):
            raise _bad("/target/name", "the target's name must end in .ies or .ldt")
        if len(target["text"]) > MAX_TARGET_CHARS:
            raise _bad("/target/text", f"the file is larger than {MAX_TARGET_CHARS} "
                                       "characters")
        vary = body.get("vary")
        if not isinstance(vary, list) or not vary or not all(
                isinstance(v, str) and v.strip() for v in vary):
            raise _bad("/vary", "give the parameters to vary as a list of "
                                "'PATH.PROPERTY[=LO:HI]' strings, at least one")
        numbers = {}
        for key, default, lo, hi in (("evaluations", EVALUATIONS, 2, MOST_EVALUATIONS),
                                     ("photons", PHOTONS, 1024, MOST_PHOTONS),
                                     ("seed", 0, 0, 2 ** 31 - 2)):
            v = body.get(key, default)
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
                raise _bad(f"/{key}", f"must be a whole number from {lo:,} to {hi:,}")
            numbers[key] = v
        final = body.get("final_error", 0.05)
        if isinstance(final, bool) or not isinstance(final, (int, float)) or \
                not 0.005 <= final <= 0.5:
            raise _bad("/final_error", "must be a number from 0.005 to 0.5")
        unknown = set(body) - {"target", "vary", "evaluations", "photons", "seed",
                               "final_error"}
        if unknown:
            raise _bad("/" + sorted(unknown)[0], "not a field of a fit request")
        return cls(name, target["text"], tuple(v.strip() for v in vary),
                   numbers["evaluations"], numbers["photons"], numbers["seed"], float(final))


def revision_target(kept, revision) -> dict:
    """A kept revision as a fit's target: its last preview's grid (cd, every plane)
    written as an IES file's text, ``{"name", "text"}``, as an uploaded file is given;
    a :class:`DeltaError` where ``revision`` is not a number (422) or not kept (404)."""
    from ..photometry.grid import CGammaGrid
    from ..photometry.lm63 import format_ies
    from .viewer import read_frame

    if isinstance(revision, bool) or not isinstance(revision, int):
        raise _bad("/target/revision", "must be a revision number")
    data = kept.get(revision)
    if data is None:
        raise DeltaError([Problem("/target/revision", f"no preview of revision {revision} "
                                  "is kept (the kept ones: GET /revisions)")], 404)
    header, arrays = read_frame(data)
    c, cd = np.asarray(header["c"], np.float64), np.asarray(arrays["grid"], np.float64)
    if c[-1] < 360.0 - 1e-9:  # every plane, as a file lists them: 360 repeats 0
        c, cd = np.append(c, 360.0), np.vstack([cd, cd[:1]])
    grid = CGammaGrid(c, np.asarray(header["gamma"], np.float64), cd, "none")
    text = format_ies(grid, float(header.get("lamp_lumens") or 1000.0), 0.0, 0.0, 0.0,
                      {"TEST": f"revision {revision}'s preview ({header.get('photons')} "
                               "photons), the live view's fit target"})
    return {"name": f"revision-{revision}.ies", "text": text}


def _curves(objective, m) -> dict | None:
    """The best candidate's and the target's curves in the planes of
    :data:`CURVE_PLANES` (cd/klm, each of its own flux over the match grid): {"gamma":
    [...], "planes": {C: {"best": [...], "target": [...]}}}, C and C + 180 as one curve
    from -180 to 180 deg."""
    if m is None or m.candela is None or objective.target is None:
        return None
    from ..fit.objective import C_STEP  # the match grid's planes
    from ..photometry.measured import planes_kept

    c_kept, target, omega = objective.match_grid()
    gamma = objective.gammas()
    n = int(round(360.0 / C_STEP))
    rep, kept = planes_kept(objective.symmetry, n)
    slot = {int(k): i for i, k in enumerate(kept)}
    best = np.asarray(m.candela, np.float64)
    per_klm = [1000.0 / max(float((omega * v).sum()), 1e-300) for v in (best, target)]
    planes = {}
    for c in CURVE_PLANES:
        rows = [slot[int(rep[int(round(a / C_STEP)) % n])] for a in (c + 180.0, c)]
        curve = {}
        for key, values, k in (("best", best, per_klm[0]), ("target", target, per_klm[1])):
            back, front = values[rows[0]], values[rows[1]]
            curve[key] = [round(float(v) * k, 4) for v in np.concatenate([back[::-1],
                                                                           front[1:]])]
        planes[f"{c:g}"] = curve
    angles = np.concatenate([-gamma[::-1], gamma[1:]])
    return {"gamma": [float(a) for a in angles], "planes": planes}


def _end_with_parent() -> None:
    """End this process at once when the service that started it is gone (killed): a
    fit nobody follows would trace on, and its next message would wait for a reader
    forever."""
    parent = multiprocessing.parent_process()
    if parent is None:
        return

    def watch() -> None:
        parent.join()
        os._exit(3)

    threading.Thread(target=watch, name="lumitrace-fit-parent", daemon=True).start()


def _start_layer(stage: str, luminaire: str | None, edits: str | None,
                 vary: tuple[str, ...]) -> str:
    """The parameters' values when the fit starts, as a layer fragment: the delta that
    undoes the best's (the same attributes, the values they had)."""
    from ..fit.candidates import CandidateStage
    from ..fit.parameters import resolve

    cs = CandidateStage(stage, luminaire, edits)
    params = resolve(cs.stage, list(vary))
    cs.author(params, [p.start for p in params])
    return cs.layer.ExportToString()


def _child(stage: str, edits: str | None, luminaire: str | None, folder: str,
           request: FitRequest, messages, stop) -> None:
    """The fit's process: run it, telling ``messages`` of each generation and of the end;
    ``stop`` (an Event) ends the search before its next generation."""
    _end_with_parent()
    try:
        from ..fit.objective import Objective
        from ..fit.run import FitOptions, run_fit
        from ..fit.target import read_target

        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        target = out / ("target" + Path(request.target_name).suffix.lower())
        target.write_text(request.target_text, encoding="latin-1" if target.suffix ==
                          ".ldt" else "utf-8", errors="replace")
        objective = Objective(read_target(target))
        undo = _start_layer(stage, luminaire, edits, request.vary)
        opts = FitOptions(stage=Path(stage), vary=list(request.vary), target=target,
                          photons=request.photons, evaluations=request.evaluations,
                          seed=request.seed, final_error=request.final_error, out=out,
                          luminaire=luminaire, pictures=False,
                          edits=Path(edits) if edits else None,
                          fresh=True)
        started = time.perf_counter()
        count = [0]

        def watch(batch, measured):
            count[0] += len(batch)
            best = min(batch, key=lambda e: e.merit)
            messages.put({"kind": "generation", "generation": best.generation,
                          "evaluations": count[0], "seconds": time.perf_counter() - started,
                          "merit": best.merit, "merit_error": best.merit_error,
                          "photons": best.photons,
                          "values": dict(zip((v.split("=", 1)[0] for v in request.vary),
                                             best.values)),
                          "curves": _curves(objective, measured)})

        messages.put({"kind": "started"})
        summary = run_fit(opts, watch=watch, should_stop=stop.is_set)
        layer = Path(summary["edits"]).read_text(encoding="utf-8")
        messages.put({"kind": "done", "summary": summary, "layer": layer, "undo": undo})
    except BaseException as exc:  # noqa: BLE001 (told to the page, whatever it is)
        messages.put({"kind": "failed", "error": str(exc) or type(exc).__name__})


@dataclass
class FitState:
    """What the page is shown of the fit: its state (idle, starting, running, stopping,
    done, failed), the request, the merit after each generation, the best so far, its
    curves, the summary and the layer of the confirmed best, or the error."""

    state: str = "idle"
    number: int = 0
    request: dict | None = None
    history: list = field(default_factory=list)
    best: dict | None = None
    curves: dict | None = None
    summary: dict | None = None
    layer: str | None = None
    undo: str | None = None
    error: str | None = None
    applied: int | None = None

    def as_dict(self) -> dict:
        return {"state": self.state, "fit": self.number, "request": self.request,
                "history": self.history, "best": self.best, "curves": self.curves,
                "summary": self.summary, "error": self.error, "applied": self.applied,
                "can_apply": self.layer is not None}


class LiveFit:
    """The live view's fit: at most one running, in its own process."""

    def __init__(self, stage_path: Path, edits_path: Path, luminaire: str | None,
                 folder: Path, publish):
        self.stage_path, self.edits_path, self.luminaire = stage_path, edits_path, luminaire
        self.folder = Path(folder)
        self.publish = publish
        self._lock = threading.Lock()
        # numbered on from the folder's fits: an earlier session's are never overwritten
        self._state = FitState(number=_last_number(self.folder))
        self._process = None
        self._stop = None

    def status(self) -> dict:
        with self._lock:
            return self._state.as_dict()

    def start(self, request: FitRequest) -> dict:
        """Start a fit (refused, 409, while one runs)."""
        with self._lock:
            if self._state.state in ("starting", "running", "stopping"):
                raise DeltaError([Problem("/fit", f"fit {self._state.number} is still "
                                          "running: stop it first")], 409)
            ctx = multiprocessing.get_context("spawn")
            messages, self._stop = ctx.Queue(), ctx.Event()
            number = self._state.number + 1
            edits = str(self.edits_path) if self.edits_path.is_file() else None
            self._state = FitState("starting", number, {
                "target": request.target_name, "vary": list(request.vary),
                "evaluations": request.evaluations, "photons": request.photons,
                "seed": request.seed, "final_error": request.final_error})
            self._process = ctx.Process(
                target=_child, name=f"lumitrace-fit-{number}",
                args=(str(self.stage_path), edits, self.luminaire,
                      str(self.folder / f"fit-{number}"), request, messages, self._stop))
            self._process.start()
            threading.Thread(target=self._follow, args=(number, self._process, messages),
                             name="lumitrace-fit-follow", daemon=True).start()
            state = self._state.as_dict()
        self.publish("fit", fit=number, state="starting")
        return state

    def _follow(self, number: int, process, messages) -> None:
        """Read the fit's messages until it ends (or its process dies without a word)."""
        while True:
            try:
                msg = messages.get(timeout=0.5)
            except queue.Empty:
                if process.is_alive():
                    continue
                try:  # what it said just before it ended
                    msg = messages.get(timeout=0.5)
                except queue.Empty:
                    msg = {"kind": "failed", "error": f"the fit's process ended (exit "
                                                      f"code {process.exitcode})"}
            kind = msg["kind"]
            with self._lock:
                s = self._state
                if kind == "started":
                    s.state = "stopping" if self._stop.is_set() else "running"
                elif kind == "generation":
                    s.history.append({k: msg[k] for k in ("generation", "evaluations",
                                                          "seconds", "merit",
                                                          "merit_error", "photons")})
                    s.best, s.curves = msg["values"], msg["curves"] or s.curves
                elif kind == "done":
                    s.state, s.summary, s.layer = "done", msg["summary"], msg["layer"]
                    s.undo = msg["undo"]
                    s.best = msg["summary"]["best"]
                else:
                    s.state, s.error = "failed", msg["error"]
                event = {"fit": number, "state": s.state}
                if s.history:
                    event |= {"evaluations": s.history[-1]["evaluations"],
                              "merit": _finite(s.history[-1]["merit"])}
            self.publish("fit", **event)
            if kind in ("done", "failed"):
                process.join(END_WAIT)
                return

    def stop(self) -> dict:
        """Ask the running fit to end its search; its best so far is then confirmed."""
        with self._lock:
            if self._state.state not in ("starting", "running"):
                raise DeltaError([Problem("/fit", "no fit is running")], 409)
            self._stop.set()
            self._state.state = "stopping"
            state = self._state.as_dict()
        self.publish("fit", fit=state["fit"], state="stopping")
        return state

    def layer_to_apply(self) -> tuple[int, str, str]:
        """The confirmed best's layer, to apply as a delta, and the layer that undoes it
        (the values at the fit's start); 409 where there is none."""
        with self._lock:
            if self._state.layer is None:
                raise DeltaError([Problem("/fit", "no finished fit to apply")], 409)
            return self._state.number, self._state.layer, self._state.undo

    def applied(self, number: int, revision: int) -> None:
        with self._lock:
            if self._state.number == number:
                self._state.applied = revision

    def close(self) -> None:
        """End a running fit (the service is stopping)."""
        with self._lock:
            process, stop = self._process, self._stop
        if process is not None and process.is_alive():
            stop.set()
            process.join(END_WAIT)
            if process.is_alive():
                process.terminate()
                process.join(END_WAIT)


def _last_number(folder: Path) -> int:
    """The largest N of the ``fit-N`` folders in ``folder`` (0: none)."""
    numbers = [int(p.name[4:]) for p in folder.glob("fit-*") if p.name[4:].isdigit()] \
        if folder.is_dir() else []
    return max(numbers, default=0)


def _finite(x):
    return x if isinstance(x, (int, float)) and math.isfinite(x) else None
