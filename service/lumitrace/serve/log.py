"""What a running service says on stderr: one line per event an operator follows (a
revision and its source, the share of photons retraced, a restart and why, a result
written, a revision done, warnings, errors, stopping); ``lumitrace serve --quiet``
silences it. Iterations are left to the event stream: they come several a second."""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any, Callable, TextIO

from .events import Event, EventLog

#: Events not written to stderr (frequent, and in the event stream for who wants them).
QUIET_KINDS = {"iteration"}


def _revision(data: dict[str, Any]) -> str:
    return f"revision {data.get('revision')}"


def _percent(value) -> str:
    return f"{100 * value:.2f}%" if isinstance(value, (int, float)) else "undefined"


def _revision_line(d: dict[str, Any]) -> str:
    effect = d.get("effect") or {}
    touched = [*effect.get("emitters", ()), *effect.get("materials", ()),
               *effect.get("parts", ())]
    source = d.get("source")
    if source == "file" and d.get("layers"):
        source += ": " + ", ".join(Path(p).name for p in d["layers"])
    what = f" ({', '.join(touched[:4])}{', ...' if len(touched) > 4 else ''})" \
        if touched else ""
    return f"{_revision(d)} from {source}: effect {effect.get('kind')}{what}"


def _retrace_line(d: dict[str, Any]) -> str:
    photons, of = d.get("photons") or 0, d.get("of") or 0
    share = f" ({100 * photons / of:.1f}%)" if of else ""
    rebuilt = d.get("rebuilt_parts")
    parts = f"; Embree parts rebuilt: {', '.join(rebuilt)}" if rebuilt else ""
    return (f"{_revision(d)}: retraced {photons:,} of {of:,} photons{share} in "
            f"{d.get('seconds', 0):.2f} s{parts}")


def _written_line(d: dict[str, Any]) -> str:
    pictures = " with pictures" if d.get("pictures") else ""
    return (f"{_revision(d)}: written{pictures} ({d.get('photons') or 0:,} photons, "
            f"error {_percent(d.get('relative_error'))}, {d.get('seconds', 0):.2f} s)")


def _done_line(d: dict[str, Any]) -> str:
    converged = "converged" if d.get("converged") else "not converged"
    return (f"{_revision(d)}: done, {d.get('photons') or 0:,} photons, error at most "
            f"{_percent(d.get('relative_error_bound'))} ({converged})")


_LINES: dict[str, Callable[[dict[str, Any]], str]] = {
    "started": lambda d: f"started at revision {d.get('revision')}, {d.get('url')}",
    "revision": _revision_line,
    "retrace": _retrace_line,
    "restart": lambda d: f"{_revision(d)}: traced afresh: {d.get('reason')}",
    "written": _written_line,
    "done": _done_line,
    "warning": lambda d: f"warning: {d.get('message')}",
    "error": lambda d: f"error: {d.get('message')}",
    "stopping": lambda d: f"stopping at revision {d.get('revision')}",
}


def event_line(event: Event) -> str | None:
    """The stderr line of ``event`` (None for kinds left to the stream), stamped with the
    local time."""
    if event.kind in QUIET_KINDS:
        return None
    say = _LINES.get(event.kind)
    text = say(event.data) if say is not None else \
        f"{event.kind}: " + ", ".join(f"{k} {v}" for k, v in event.data.items())
    return f"{time.strftime('%H:%M:%S', time.localtime(event.time))} {text}"


async def echo_events(events: EventLog, stream: TextIO | None = None) -> None:
    """Write each event's line to ``stream`` (stderr) until the log is closed, the last
    events included."""
    stream = stream or sys.stderr
    last = events.first_id - 1
    while True:
        closed = events.closed
        batch = await events.wait(last, 3600.0)
        for event in batch:
            line = event_line(event)
            if line is not None:
                try:
                    print(line, file=stream, flush=True)
                except (OSError, ValueError):  # stderr closed: the service serves on
                    return
        if batch:
            last = batch[-1].id
        if closed or (events.closed and not batch):
            return
