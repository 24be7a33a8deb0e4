"""The fit's journal: one JSON line per generation, so an interrupted fit resumes.

The first line says which fit it is (a hash of the stage's scene, the parameters, the
target, the objective, the seed and the photon settings); each generation's line holds its
candidates' values and merits, the photons of the next generation and the optimiser's whole
state (pickled). A line is written whole (held against the signals a command stops on) and
flushed to disk before the next generation starts; a last line cut short by a crash is
ignored. A fit started again with the same inputs reads the journal and goes on from its
last generation: the optimiser's state includes its random generator, so the resumed fit
asks for the very candidates the uninterrupted one would have.
"""
from __future__ import annotations

import base64
import json
import os
import pickle
from contextlib import nullcontext
from pathlib import Path

from ..errors import warn

#: Journal file name in the fit's folder.
JOURNAL = "fit.journal"
VERSION = 1


def _held():
    try:
        from ..publish.transaction import signals_held
    except ImportError:  # pragma: no cover
        return nullcontext()
    return signals_held()


class Journal:
    """The journal at ``folder/fit.journal`` of the fit named by ``key``."""

    def __init__(self, folder: Path, key: str):
        self.path = Path(folder) / JOURNAL
        self.key = key

    def load(self, fresh: bool = False) -> list[dict]:
        """The generations of this fit already journalled (none where the journal is of
        another fit, with a warning, or ``fresh``); the journal is (re)started when
        there are none."""
        generations = []
        if self.path.exists() and not fresh:
            lines = self.path.read_text(encoding="utf-8").splitlines()
            records = []
            for i, line in enumerate(lines):
                try:
                    records.append(json.loads(line))
                except json.JSONDecodeError:
                    if i != len(lines) - 1:
                        warn(f"{self.path}: line {i + 1} is damaged: the fit starts afresh")
                        records = []
                    break  # a last line cut short by a crash
            head = records[0] if records else {}
            if head.get("kind") == "header" and head.get("key") == self.key and \
                    head.get("version") == VERSION:
                generations = [r for r in records[1:] if r.get("kind") == "generation"]
            elif records:
                warn(f"{self.path} is the journal of another fit (other stage, parameters, "
                     "target, objective or settings): this fit starts afresh and replaces it")
        if not generations:
            self._write([{"kind": "header", "version": VERSION, "key": self.key}], "w")
        elif self._tail_damaged():
            self._rewrite(generations)
        return generations

    def _tail_damaged(self) -> bool:
        text = self.path.read_bytes()
        return bool(text) and not text.endswith(b"\n")

    def _rewrite(self, generations: list[dict]) -> None:
        self._write([{"kind": "header", "version": VERSION, "key": self.key}] + generations,
                    "w")

    def append(self, generation: dict) -> None:
        """Add one generation's line, whole, flushed to disk."""
        self._write([generation], "a")

    def _write(self, records: list[dict], mode: str) -> None:
        text = "".join(json.dumps(r, separators=(",", ":")) + "\n" for r in records)
        with _held():
            with open(self.path, mode, encoding="utf-8") as fh:
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())


def pack_state(obj) -> str:
    """An optimiser's state as journal text."""
    return base64.b64encode(pickle.dumps(obj, protocol=4)).decode("ascii")


def unpack_state(text: str):
    """The state :func:`pack_state` wrote (the journal is the fit's own file)."""
    return pickle.loads(base64.b64decode(text.encode("ascii")))
