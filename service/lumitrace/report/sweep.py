"""A sweep: many stages and the variants of their variant sets, each traced and written as
``lumitrace trace`` writes it, into a folder of its own, with one results table.

A case is one stage with one selection per variant set of its luminaire prim (every
combination by default). Its outputs go to ``OUT/NAME/`` or ``OUT/NAME/SET-VALUE,...``,
never sublayered into the stage (variants would fight over it), with the case's row of the
table, ``sweep-case.json``, written after them. The table (:mod:`.sweep_table`) is made
from those per-case records after every case, so it lists every case whose record is in
``OUT`` (another sweep's into the same folder too), and a sweep stopped part-way and
started again traces only the cases whose results are not current: same input hash (scene
and the settings that shape the map), same stop criterion, result layer still there.

One sweep at a time writes into a folder: a second one is refused at once, naming the
first (its process, start and command line), by a lock the kernel releases when the first
ends however it ends. A case that fails (a variant whose values the stage reader refuses,
a stage that cannot be read, outputs it may not replace) is one failed row, named with its
reason; the other cases run.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import glob
import itertools
import json
import os
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Callable

from ..atomic import write_text
from ..errors import ClusterLost, LumitraceError
from ..filenames import EDITS_LAYER_SUFFIX, RESULT_LAYER_SUFFIX, stage_name
from . import sweep_table

#: Stage files a folder contributes (our own layers excluded).
STAGE_SUFFIXES = (".usda", ".usdc", ".usd", ".usdz")
#: The lock file of a sweep's folder, and each case's record (its row of the table).
LOCK = ".lumitrace-sweep.lock"
CASE_RECORD = "sweep-case.json"


@dataclass(frozen=True)
class Case:
    """One trace of a sweep: ``stage`` with ``variants`` ((set, value), ...) selected on
    its luminaire prim, written into ``folder``."""

    stage: Path
    variants: tuple[tuple[str, str], ...]
    folder: Path
    #: why the case cannot run (its stage could not be read to plan it), or empty
    error: str = ""

    @property
    def label(self) -> str:
        """``SET=VALUE, ...`` (empty: the stage as it composes)."""
        return ", ".join(f"{s}={v}" for s, v in self.variants)

    @property
    def key(self) -> str:
        return f"{self.stage}|{self.label}"

    @property
    def name(self) -> str:
        """``STAGE.usda [SET=VALUE, ...]``: the case in messages."""
        return f"{self.stage.name} [{self.label}]" if self.label else self.stage.name


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
    to vary and their values, empty lists meaning all; None: every set, every value). A
    stage that cannot be opened is one case, failed with the reason."""
    cases = []
    seen: set[str] = set()
    for stage in stages:
        try:
            sets = variant_sets(stage)
        except Exception as exc:  # noqa: BLE001 - USD's errors: the case says why
            cases.append(Case(stage, (), out / stage_name(stage),
                              error=f"cannot open the stage: {_reason(exc)}"))
            continue
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


def _reason(exc: BaseException) -> str:
    """One line saying why, from a lumitrace error or USD's."""
    from ..stage.diagnostics import tf_message

    text = str(exc) if isinstance(exc, (LumitraceError, OSError)) else tf_message(exc)
    return " ".join(text.split()) or type(exc).__name__


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
    if not row or not row.get("complete") or row.get("error") or \
            row.get("input_hash") != expected_hash or row.get("request") != _request(settings):
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


def read_record(folder: Path) -> dict | None:
    """The row a case's folder records (:data:`CASE_RECORD`), None where it has none."""
    try:
        row = json.loads((folder / CASE_RECORD).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return row if isinstance(row, dict) and "key" in row else None


def recorded_rows(out: Path) -> list[dict]:
    """Every case's row recorded in the sweep folder ``out`` (``OUT/NAME/`` and
    ``OUT/NAME/SUB/``), by stage and variant: what the table is made of."""
    rows = []
    for record in sorted(out.glob(f"*/{CASE_RECORD}")) + sorted(out.glob(f"*/*/{CASE_RECORD}")):
        row = read_record(record.parent)
        if row is not None:
            rows.append(row)
    return sorted(rows, key=lambda r: (str(r.get("stage")), str(r.get("variant"))))


def _record(case: Case, row: dict) -> None:
    case.folder.mkdir(parents=True, exist_ok=True)
    write_text(case.folder / CASE_RECORD, json.dumps(row, indent=1) + "\n")


def _write_table(out: Path, traced: dict[str, bool]) -> list[dict]:
    """The table and the overview from the records in ``out`` (``traced``: whether this
    sweep traced a case, by key); returns the rows."""
    rows = [{**r, "traced": traced.get(r["key"], False)} for r in recorded_rows(out)]
    sweep_table.write(out, rows)
    return rows


@contextlib.contextmanager
def locked_folder(out: Path):
    """Hold the sweep lock of the folder ``out`` for the block; refuse at once (a
    :class:`LumitraceError`) where another sweep holds it, naming it."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / LOCK
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
            raise LumitraceError(f"cannot create the sweep's lock file: {exc.strerror}",
                                 str(path)) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            holder = os.pread(fd, 4096, 0).decode(errors="replace")
            os.close(fd)
            if exc.errno not in (errno.EAGAIN, errno.EACCES):
                raise
            raise LumitraceError(f"another sweep is writing into this folder ({_holder(holder)})"
                                 ": wait for it to end, or give this one another --out",
                                 str(out)) from None
        try:
            same = os.stat(path, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)  # its holder removed it as we opened it: lock the file named now
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps({"pid": os.getpid(), "started": time.strftime(
            "%Y-%m-%d %H:%M:%S"), "command": "lumitrace " + shlex.join(sys.argv[1:])}).encode(), 0)
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)  # still held: a sweep waiting finds it gone
        os.close(fd)


def _holder(text: str) -> str:
    try:
        h = json.loads(text)
        return f"pid {h['pid']}, started {h['started']}: {h['command']}"
    except (ValueError, KeyError, TypeError):
        return "a sweep whose lock names nothing"


def run_sweep(cases: list[Case], settings, out: Path, pictures: bool = False,
              log: Callable[[str], None] | None = None) -> list[dict]:
    """Trace every case whose results are not current, each recorded in its folder; write
    the table and the overview (from every case recorded in ``out``) after each; return
    this sweep's rows (``traced``: whether it traced the case; ``error``: why a case
    failed). The folder is locked meanwhile (:func:`locked_folder`)."""
    with locked_folder(out):
        return _run_cases(cases, settings, out, pictures, log)


def _run_cases(cases: list[Case], settings, out: Path, pictures: bool,
               log: Callable[[str], None] | None) -> list[dict]:
    from ..publish.outputs import claim_planned_outputs, write_outputs
    from ..publish.record import input_hash
    from ..run.session import run

    rows: list[dict] = []
    traced: dict[str, bool] = {}
    for i, case in enumerate(cases):
        lost = None
        try:
            if case.error:
                raise LumitraceError(case.error, str(case.stage))
            scene = read_case(case)
            expected = input_hash(SimpleNamespace(scene=scene, settings=settings))
            old = read_record(case.folder)
            if _current(old, case, expected, settings):
                rows.append({**old, "traced": False})
                traced[case.key] = False
                if log:
                    log(f"[{i + 1}/{len(cases)}] {case.name}: current")
                continue
            case.folder.mkdir(parents=True, exist_ok=True)
            claim_planned_outputs(scene, case.folder)
            t0 = time.perf_counter()
            try:
                result = run(scene, settings)
            except ClusterLost as exc:  # the batches that finished are written, then said
                result, lost = exc.result, exc
            record = write_outputs(result, case.folder, sublayer=False, pictures=pictures)
            row = sweep_table.row(case, record, expected, _request(settings),
                                  complete=lost is None, wall=time.perf_counter() - t0)
            said = f"{record['photons']:,} photons, {record['seconds']:.1f} s"
        except ClusterLost:
            raise
        except Exception as exc:  # noqa: BLE001 - lumitrace's and USD's errors: one row
            from pxr import Tf

            if not isinstance(exc, (LumitraceError, OSError, Tf.ErrorException)):
                raise
            row = sweep_table.failed_row(case, f"{case.name}: {_reason(exc)}")
            said = f"failed: {_reason(exc)}"
        row = {**row, "traced": not row.get("error")}
        _record(case, row)
        rows.append(row)
        traced[case.key] = row["traced"]
        _write_table(out, traced)
        if log:
            log(f"[{i + 1}/{len(cases)}] {case.name}: {said}")
        if lost is not None:
            raise lost.written(record["photons"])
    _write_table(out, traced)
    return rows
