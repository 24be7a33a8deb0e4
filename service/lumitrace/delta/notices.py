"""USD's own account of what changed: ``Usd.Notice.ObjectsChanged`` collected into the
paths of changed prims and properties."""
from __future__ import annotations

from pxr import Tf, Usd


class ChangedPaths:
    """While alive, collects the paths USD reports as changed on ``stage`` (resyncs and
    value or metadata edits). Notices arrive on the thread that edits the stage."""

    def __init__(self, stage: Usd.Stage):
        self._paths: set[str] = set()
        self._key = Tf.Notice.Register(Usd.Notice.ObjectsChanged, self._changed, stage)

    def _changed(self, notice, _sender) -> None:
        for path in list(notice.GetResyncedPaths()) + list(notice.GetChangedInfoOnlyPaths()):
            self._paths.add(str(path))

    def take(self) -> list[str]:
        """The paths collected since the last call, sorted; clears them."""
        paths, self._paths = sorted(self._paths), set()
        return paths

    def close(self) -> None:
        if self._key is not None:
            self._key.Revoke()
            self._key = None
