"""The service's event log: numbered events kept in a bounded ring, published from any
thread, followed by any number of server-sent-event streams that resume by id."""
from __future__ import annotations

import asyncio
import collections
import itertools
import json
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

#: Events kept for clients that reconnect (older ones are gone: the stream says so).
EVENT_HISTORY = 4096


@dataclass(frozen=True)
class Event:
    """One event: ``id`` increases by one per event over the service's life."""

    id: int
    kind: str
    data: dict[str, Any]
    time: float

    def as_dict(self) -> dict[str, Any]:
        return {"id": self.id, "event": self.kind,
                "data": json.loads(self._data_json())}

    def _data_json(self) -> str:
        return json.dumps({**self.data, "time": self.time}, allow_nan=False,
                          default=_json_default)

    def sse(self) -> bytes:
        """The event as a server-sent-events frame."""
        return f"id: {self.id}\nevent: {self.kind}\ndata: {self._data_json()}\n\n".encode()


def _json_default(obj):
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if isinstance(obj, (set, frozenset, tuple)):
        return list(obj)
    return str(obj)


class EventLog:
    """Thread-safe publishing; asyncio waiting on the loop given to :meth:`bind`.

    Ids start at ``first_id`` (above every id an earlier service of the stage used);
    ``reserve(upto)`` is called, before ids up to ``upto`` are used, once per ``block``
    of them, so that the next service can start above them even after a kill -9."""

    def __init__(self, history: int = EVENT_HISTORY, first_id: int = 1,
                 reserve: Callable[[int], None] | None = None, block: int = 1024):
        self._events: collections.deque[Event] = collections.deque(maxlen=history)
        self.first_id = first_id
        self._ids = itertools.count(first_id)
        self._reserve, self._block = reserve, block
        self._reserved = first_id - 1
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._changed: asyncio.Condition | None = None
        self.closed = False

    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._changed = asyncio.Condition()

    def publish(self, kind: str, **data: Any) -> Event:
        """Add an event (from any thread) and wake the streams."""
        with self._lock:
            number = next(self._ids)
            if self._reserve is not None and number > self._reserved:
                self._reserved = number - 1 + self._block
                self._reserve(self._reserved)
            event = Event(number, kind, data, time.time())
            self._events.append(event)
        self._wake()
        return event

    def close(self) -> None:
        """End every stream (the service is stopping)."""
        self.closed = True
        self._wake()

    def _wake(self) -> None:
        loop = self._loop
        if loop is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(lambda: asyncio.ensure_future(self._notify()))
            except RuntimeError:  # the loop is closing
                pass

    async def _notify(self) -> None:
        async with self._changed:
            self._changed.notify_all()

    def since(self, last_id: int) -> list[Event]:
        """Events after ``last_id`` still in the ring, oldest first."""
        with self._lock:
            return [e for e in self._events if e.id > last_id]

    def newest_id(self) -> int:
        """The id of the newest event (``first_id - 1`` before any)."""
        with self._lock:
            return self._events[-1].id if self._events else self.first_id - 1

    def before_revision(self, revision: int) -> tuple[int, dict[str, Any] | None]:
        """Where a client following from ``revision`` starts: after the event before the
        first kept event of that revision or a later one (after the newest event where
        there is none yet), and the gap to report where the ring has dropped older events
        and the first kept one is of a later revision already."""
        with self._lock:
            kept = list(self._events)
        earlier = False  # a kept event of an earlier revision: nothing of this one is lost
        for e in kept:
            number = e.data.get("revision")
            if not isinstance(number, int):
                continue
            if number >= revision:
                lost = not earlier and number > revision and kept[0].id > self.first_id
                return e.id - 1, {"missed_before": e.id, "restart": False} if lost else None
            earlier = True
        return (kept[-1].id if kept else self.first_id - 1), None

    def oldest_id(self) -> int:
        with self._lock:
            return self._events[0].id if self._events else 0

    def resume(self, last_id: int) -> tuple[int, dict[str, Any] | None]:
        """Where a client resuming after ``last_id`` goes on from, and the ``gap`` it must
        be told of (None: none): events it missed that are no longer kept, or a restart
        of the service since (an id from before this service's first, or one it never
        handed out). After a restart it gets everything this service kept."""
        with self._lock:
            oldest = self._events[0].id if self._events else self.first_id
            newest = self._events[-1].id if self._events else self.first_id - 1
        if not last_id:
            return 0, None
        if last_id < self.first_id or last_id > newest:
            return 0, {"missed_before": oldest, "restart": True, "first_id": self.first_id,
                       "reason": f"the service restarted: its events start at "
                                 f"{self.first_id}, event {last_id} is of an earlier one"}
        if oldest > last_id + 1:
            return last_id, {"missed_before": oldest, "restart": False}
        return last_id, None

    async def wait(self, last_id: int, timeout: float) -> list[Event]:
        """Events after ``last_id``; waits up to ``timeout`` s for one."""
        events = self.since(last_id)
        if events or self.closed:
            return events
        async with self._changed:
            try:
                await asyncio.wait_for(
                    self._changed.wait_for(lambda: self.closed or bool(self.since(last_id))),
                    timeout)
            except asyncio.TimeoutError:
                pass
        return self.since(last_id)
