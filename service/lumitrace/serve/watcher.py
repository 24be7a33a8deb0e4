"""Layer files edited on disk, seen with ``watchfiles`` and turned into revisions.

The watcher follows the folders of every layer the stage uses; a change to a file that is
not one of them, or to one whose content is what the service last read or wrote, is
ignored. A file that cannot be read (a program half-way through saving it) or is gone is
retried for :data:`RETRY_SECONDS`, then reported, and the last good revision stays; when
it is back, even unchanged, it is a revision (the results and ``last_error`` recover).
"""
from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Callable, Optional

from ..errors import StageError
from .events import EventLog
from .live import LayerUnreadable, LiveStage, Revision

#: Debounce of the file watcher (ms): saves closer together than this are one change.
DEBOUNCE_MS = 30
#: The watcher reports in after this long without a change (ms): its first report, once
#: it watches, is when the files are compared with what the service read, so a save made
#: between the service's start (or a new folder's) and the watch is not lost.
WATCH_STARTED_MS = 200
#: How long an unreadable layer file is retried before it is reported (s).
RETRY_SECONDS = 3.0
RETRY_STEP = 0.1


async def watch_layers(live: LiveStage, submit: Callable[[Revision], None],
                       events: EventLog, stop: asyncio.Event,
                       report: Optional[Callable[[str], None]] = None) -> None:
    """Watch until ``stop`` is set; ``submit`` gets each new revision, ``report`` each
    error (for ``/status``'s ``last_error``) besides its event."""
    from watchfiles import awatch

    while not stop.is_set():
        folders = await live.acall(live.folders)
        first = True
        async for changes in awatch(*sorted(map(str, folders)), stop_event=stop,
                                    debounce=DEBOUNCE_MS, step=10, recursive=False,
                                    watch_filter=None, yield_on_timeout=True,
                                    rust_timeout=WATCH_STARTED_MS):
            paths = {Path(p).absolute() for _, p in changes}
            if first:  # the watch is up: a save made before it started is found by content
                first = False
                paths |= await live.acall(lambda: live.layer_files() | live.asset_files())
            if not paths:
                continue
            await _reload(live, paths, submit, _Errors(events, report))
            if await live.acall(live.folders) != folders:
                break  # a layer in a new folder: watch it too


class _Errors:
    """Where the watcher's errors go: an ``error`` event, and ``report``."""

    def __init__(self, events: EventLog, report: Optional[Callable[[str], None]]):
        self.events = events
        self.report = report

    def publish(self, kind: str, message: str, **data) -> None:
        self.events.publish(kind, message=message, **data)
        if self.report is not None:
            self.report(message)


async def _reload(live: LiveStage, paths: set[Path], submit, events: _Errors) -> None:
    clock = asyncio.get_running_loop().time
    since = clock()  # the retries' window is wall time, however long each read takes
    while True:
        try:
            revision = await live.acall(live.reload, paths)
        except LayerUnreadable as exc:
            if clock() - since >= RETRY_SECONDS:
                await live.acall(live.trouble, exc.path)  # its return is a revision
                events.publish("error", message=f"{exc} (keeping revision {live.revision})",
                               where=exc.where)
                return
            await asyncio.sleep(RETRY_STEP)
            continue
        except StageError as exc:
            events.publish("error", message=f"the edited stage cannot be traced: {exc} "
                                            f"(keeping revision {live.revision})",
                           where=exc.where)
            return
        if revision is not None:
            submit(revision)
        return
