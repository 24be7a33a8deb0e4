"""What a stage's service keeps across its restarts: the newest revision it handed out and
the event ids it may have used, in ``.NAME.lumitrace-serve.json`` beside the stage.

Revisions only grow for a stage: a revision started by a file saved on disk is recorded
here (a delta's is in the edits layer too), so that a restarted service never hands out a
number that already described another scene. Event ids are reserved in blocks before
they are used, so that even after a kill -9 the next service's ids start above every id
a client may hold; a client resuming with an older id is told it missed a restart.
"""
from __future__ import annotations

import json
import os
import threading
from pathlib import Path

from ..atomic import write_text_durably
from ..filenames import stage_name

#: Suffix of the state file: ``.NAME.lumitrace-serve.json`` beside ``NAME.usda``.
STATE_SUFFIX = ".lumitrace-serve.json"
#: Event ids reserved (and recorded) at a time.
EVENT_BLOCK = 1024


def state_path(stage_path: str | os.PathLike) -> Path:
    """The state file of a stage (beside the real file, as the service's lock is)."""
    stage = Path(stage_path).resolve()
    return stage.with_name("." + stage_name(stage) + STATE_SUFFIX)


class ServiceState:
    """The recorded revision and event-id reservation of one stage's service; written
    only by the service holding the stage's lock."""

    def __init__(self, path: Path, revision: int = 0, events_reserved: int = 0,
                 scene: str | None = None):
        self.path = path
        self.revision = revision
        self.events_reserved = events_reserved
        #: the content hash of the scene ``revision`` describes
        self.scene = scene
        self._lock = threading.Lock()

    @classmethod
    def of(cls, stage_path: str | os.PathLike) -> "ServiceState":
        """The stage's state as recorded (zeros where there is none, or it is garbage)."""
        path = state_path(stage_path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            data = {}
        data = data if isinstance(data, dict) else {}
        scene = data.get("scene") if isinstance(data.get("scene"), str) else None
        return cls(path, _count(data.get("revision")), _count(data.get("events_reserved")),
                   scene)

    def record_revision(self, revision: int, scene: str | None = None) -> None:
        """Record a revision handed out and the hash of its scene (durably, before anyone
        hears of it)."""
        with self._lock:
            if revision >= self.revision:
                self.revision, self.scene = revision, scene
                self._save()

    def start_revision(self, recorded: int, scene: str) -> int:
        """The revision a service starts at: the newest recorded anywhere (``recorded``:
        the edits layer's), one more when the scene it described is not the one read
        now (the stage was edited while no service ran)."""
        revision = max(recorded, self.revision)
        if revision == self.revision and self.scene not in (None, scene):
            revision += 1
        return revision

    def reserve_events(self, upto: int) -> None:
        """Record that event ids up to ``upto`` may be used (durably, before they are)."""
        with self._lock:
            if upto > self.events_reserved:
                self.events_reserved = upto
                self._save()

    def first_event_id(self) -> int:
        """The first event id of a service starting now: above every id reserved before."""
        return self.events_reserved + 1

    def _save(self) -> None:
        try:
            write_text_durably(self.path, json.dumps(
                {"revision": self.revision, "events_reserved": self.events_reserved,
                 "scene": self.scene}))
        except OSError:  # a read-only folder: the service still runs, unrecorded
            pass


def _count(value) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) and value > 0 \
        else 0
