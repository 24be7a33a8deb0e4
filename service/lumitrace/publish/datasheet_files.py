"""The files ``lumitrace datasheet`` writes: ``NAME.datasheet.html`` and
``NAME.datasheet.pdf`` in their folder, and ``NAME.datasheet.json``, the record of them (the
stage they belong to, each file's SHA-256, the result they were made from).

They follow a trace's rules (:mod:`.ownership`, :mod:`.transaction`): a file in their place
is replaced only where the record says lumitrace wrote it for this stage, unchanged since;
the three are staged and published together, or not at all, under the stage's publishing
lock. A folder holding a trace's results of the stage (its result layer) is refused: its
datasheet is ``trace --deliverables``'s, recorded in the result layer.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable, Mapping

from .. import __version__
from ..atomic import write_text
from ..digests import file_digest
from ..errors import Interrupted, OutputError, OutputWarning, warn
from ..filenames import (DATASHEET_HTML_SUFFIX, DATASHEET_PDF_SUFFIX,
                         DATASHEET_RECORD_SUFFIX, RESULT_LAYER_SUFFIX)
from .ownership import Claim, claim_files, stage_reference
from .transaction import DEFAULT_LOCK_WAIT, Transaction, locked, recover


def datasheet_paths(out: Path, name: str) -> dict[str, Path]:
    """Where the datasheet of ``NAME`` goes in ``out``: its page, its PDF and its record."""
    out = Path(out).absolute()
    return {"datasheet_html": out / f"{name}{DATASHEET_HTML_SUFFIX}",
            "datasheet_pdf": out / f"{name}{DATASHEET_PDF_SUFFIX}",
            "record": out / f"{name}{DATASHEET_RECORD_SUFFIX}"}


def read_record(path: Path) -> tuple[str | None, dict[str, str] | None]:
    """(stage reference, {file name: SHA-256}) of a datasheet record; (None, None) for a
    file that is none lumitrace wrote."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
        files = data["files"]
        reference = data["stage"]
    except (OSError, ValueError, KeyError, TypeError):
        return None, None
    if not (isinstance(files, dict) and isinstance(reference, str) and "runId" in data):
        return None, None
    return reference, {str(k): str(v) for k, v in files.items()}


def claim_datasheet(stage_path: Path, out: Path, name: str,
                    inputs: Iterable[str] = ()) -> Claim:
    """Refuse a datasheet whose files would replace one lumitrace did not write for this
    stage, or land among a trace's results (see the module's note)."""
    paths = datasheet_paths(out, name)
    layer = Path(out).absolute() / f"{name}{RESULT_LAYER_SUFFIX}"
    if layer.exists():
        raise OutputError(f"holds the results of a trace ({layer.name}), whose datasheet "
                          "is trace --deliverables's to write: write this one to another "
                          "folder (--out)", str(Path(out)))
    return claim_files(stage_path, paths["record"], read_record, paths.values(), inputs)


def publish_datasheet(data, stage_path: Path, out: Path, name: str,
                      inputs: Iterable[str] = (), about: Mapping | None = None,
                      wait: float = DEFAULT_LOCK_WAIT) -> dict[str, Path]:
    """Write the datasheet of ``data`` (a :class:`~.datasheet.DatasheetInput`) into
    ``out`` as one transaction, its record holding ``about`` too; returns the paths."""
    from .deliverables import write_datasheet

    paths = datasheet_paths(out, name)
    folder = paths["record"].parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the output folder: {exc.strerror}",
                          str(folder)) from exc
    tx = None
    try:
        with locked([folder], name, wait):
            for note in recover([folder], name, [p.name for p in paths.values()]):
                warn(note, OutputWarning)
            for note in claim_datasheet(stage_path, folder, name, inputs).notes:
                warn(note, OutputWarning)
            tx = Transaction(name, folder)
            try:
                staged = {k: tx.staged(v) for k, v in paths.items()}
                write_datasheet(data, staged["datasheet_html"], staged["datasheet_pdf"])
                record = {"stage": stage_reference(stage_path, folder),
                          "files": {paths[k].name: file_digest(staged[k])
                                    for k in ("datasheet_html", "datasheet_pdf")},
                          "runId": tx.run_id, "software": f"lumitrace {__version__}",
                          **(about or {})}
                write_text(staged["record"], json.dumps(record, indent=1) + "\n")
                tx.commit(last=paths["record"])
            except BaseException:
                tx.abort()
                raise
    except Interrupted as exc:
        exc.published = tx is not None and tx.committed
        raise
    return paths
