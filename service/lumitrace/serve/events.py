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
from typing import Any

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
    """Thread-safe publishing; asyncio waiting on the loop given to :meth:`bind`."""

    def __init__(self, history: int = EVENT_HISTORY):
        self._events: collections.deque[Event] = collections.deque(maxlen=history)
        self._ids = itertools.count(1)
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
            event = Event(next(self._ids), kind, data, time.time())
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

    def oldest_id(self) -> int:
        with self._lock:
            return self._events[0].id if self._events else 0

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
