"""A sweep: many stages and the variants of their variant sets, each traced and written as
``lumitrace trace`` writes it, into a folder of its own, with one results table.

A case is one stage with one selection per variant set of its luminaire prim (every
combination by default). Its outputs go to ``OUT/NAME/`` or ``OUT/NAME/SET-VALUE,...``,
never sublayered into the stage (variants would fight over it). The table
(:mod:`.sweep_table`) is written after every case, so a sweep stopped part-way and started
again traces only the cases whose results are not current: same input hash (scene and the
settings that shape the map), same stop criterion, result layer still there.
"""
from __future__ import annotations

import glob
import itertools
import json
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Callable

from ..errors import ClusterLost, LumitraceError
from ..filenames import EDITS_LAYER_SUFFIX, RESULT_LAYER_SUFFIX, stage_name
from . import sweep_table

#: Stage files a folder contributes (our own layers excluded).
STAGE_SUFFIXES = (".usda", ".usdc", ".usd", ".usdz")


@dataclass(frozen=True)
class Case:
    """One trace of a sweep: ``stage`` with ``variants`` ((set, value), ...) selected on
    its luminaire prim, written into ``folder``."""

    stage: Path
    variants: tuple[tuple[str, str], ...]
    folder: Path

    @property
    def label(self) -> str:
        """``SET=VALUE, ...`` (empty: the stage as it composes)."""
        return ", ".join(f"{s}={v}" for s, v in self.variants)

    @property
    def key(self) -> str:
        return f"{self.stage}|{self.label}"


def stage_files(items: list[str]) -> list[Path]:
    """The stage files named by ``items``: files, folders (their stage files) and glob
    patterns, each once, in the order given (a folder's sorted)."""
    out: list[Path] = []
    for item in items:
        p = Path(item)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.suffix in STAGE_SUFFIXES and q.is_file()
                           and not q.name.endswith((RESULT_LAYER_SUFFIX, EDITS_LAYER_SUFFIX)))
        elif p.is_file():
            found = [p]
        else:
            found = sorted(Path(g) for g in glob.glob(item) if Path(g).is_file())
        if not found:
            raise LumitraceError("no stage file here", item)
        out += [f.resolve() for f in found if f.resolve() not in out]
    names = [stage_name(f) for f in out]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise LumitraceError(f"two stages named {twice[0]}: their outputs would share a "
                             "folder; sweep them one at a time", twice[0])
    return out


def parse_variants(texts: list[str] | None) -> dict[str, list[str]] | None:
    """``--variants`` values: ``SET`` (all its variants) or ``SET=A,B``; None: every set."""
    if not texts:
        return None
    wanted: dict[str, list[str]] = {}
    for text in texts:
        name, _, values = text.partition("=")
        if not name.strip():
            raise LumitraceError(f"--variants takes SET or SET=A,B, got {text!r}")
        wanted[name.strip()] = [v.strip() for v in values.split(",") if v.strip()]
    return wanted


def variant_sets(stage_path: Path) -> dict[str, list[str]]:
    """The variant sets of the stage's luminaire (default) prim and their variants,
    lumitrace's own representation set excepted."""
    from pxr import Usd

    from ..publish.result_layer import REPRESENTATION

    stage = Usd.Stage.Open(str(stage_path))
    prim = stage.GetDefaultPrim() if stage else None
    if not prim:
        return {}
    sets = prim.GetVariantSets()
    return {n: list(sets.GetVariantSet(n).GetVariantNames()) for n in sets.GetNames()
            if n != REPRESENTATION}


def plan(stages: list[Path], wanted: dict[str, list[str]] | None, out: Path) -> list[Case]:
    """Every case: per stage, each combination of the selected variants (``wanted``: sets
    to vary and their values, empty lists meaning all; None: every set, every value)."""
    cases = []
    seen: set[str] = set()
    for stage in stages:
        sets = variant_sets(stage)
        chosen = []
        for name, values in sets.items():
            if wanted is not None and name not in wanted:
                continue
            pick = (wanted or {}).get(name) or values
            unknown = [v for v in pick if v not in values]
            if unknown:
                raise LumitraceError(f"variant set {name!r} has no variant {unknown[0]!r} "
                                     f"(it has {', '.join(values)})", str(stage))
            chosen.append([(name, v) for v in pick])
            seen.add(name)
        for combo in itertools.product(*chosen):
            sub = ",".join(f"{s}-{v}" for s, v in combo)
            folder = out / stage_name(stage) / sub if sub else out / stage_name(stage)
            cases.append(Case(stage, tuple(combo), folder))
    missing = sorted(set(wanted or ()) - seen)
    if missing:
        raise LumitraceError(f"no stage of the sweep has a variant set {missing[0]!r}")
    return cases


def read_case(case: Case):
    """The scene of ``case``: its stage composed with its variant selections (made in the
    session layer: the stage file is not touched)."""
    from pxr import Usd

    from ..stage.reader import scene_from_stage

    stage = Usd.Stage.Open(str(case.stage))
    stage.SetEditTarget(stage.GetSessionLayer())
    prim = stage.GetDefaultPrim()
    for name, value in case.variants:
        prim.GetVariantSets().GetVariantSet(name).SetVariantSelection(value)
    return scene_from_stage(stage)


def _request(settings) -> dict:
    """The stop criterion a row was traced to: a current row must have been asked the same."""
    return {"photons": settings.budget(), "seconds": settings.seconds,
            "target_error": settings.target_error}


def _current(row: dict | None, case: Case, expected_hash: str, settings) -> bool:
    if not row or not row.get("complete") or row.get("input_hash") != expected_hash or \
            row.get("request") != _request(settings):
        return False
    from pxr import Sdf

    layer_path = case.folder / (stage_name(case.stage) + RESULT_LAYER_SUFFIX)
    layer = Sdf.Layer.FindOrOpen(str(layer_path)) if layer_path.is_file() else None
    if layer is None:
        return False
    layer.Reload()
    attr = next((a for p in layer.rootPrims for a in p.attributes
                 if a.name == "lumitrace:result:inputHash"), None)
    return attr is not None and attr.default == expected_hash


def run_sweep(cases: list[Case], settings, out: Path, pictures: bool = False,
              log: Callable[[str], None] | None = None) -> list[dict]:
    """Trace every case whose results are not current; write the table and the overview
    after each; return the rows (``traced``: whether this sweep traced the case)."""
    from ..publish.outputs import claim_planned_outputs, write_outputs
    from ..publish.record import input_hash
    from ..run.session import run

    out.mkdir(parents=True, exist_ok=True)
    before = {r["key"]: r for r in sweep_table.read_rows(out)}
    rows: list[dict] = []
    for i, case in enumerate(cases):
        scene = read_case(case)
        expected = input_hash(SimpleNamespace(scene=scene, settings=settings))
        old = before.get(case.key)
        if _current(old, case, expected, settings):
            rows.append({**old, "traced": False})
            if log:
                log(f"[{i + 1}/{len(cases)}] {case.stage.name} {case.label}: current")
            continue
        case.folder.mkdir(parents=True, exist_ok=True)
        claim_planned_outputs(scene, case.folder)
        t0 = time.perf_counter()
        lost = None
        try:
            result = run(scene, settings)
        except ClusterLost as exc:  # the batches that finished are written, then said
            result, lost = exc.result, exc
        record = write_outputs(result, case.folder, sublayer=False, pictures=pictures)
        rows.append(sweep_table.row(case, record, expected, _request(settings),
                                    complete=lost is None, wall=time.perf_counter() - t0))
        sweep_table.write(out, rows + [r for r in before.values()
                                       if r["key"] not in {x["key"] for x in rows}])
        if log:
            log(f"[{i + 1}/{len(cases)}] {case.stage.name} {case.label}: "
                f"{record['photons']:,} photons, {record['seconds']:.1f} s")
        if lost is not None:
            raise lost.written(record["photons"])
    sweep_table.write(out, rows)
    return rows
