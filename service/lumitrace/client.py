"""A client of ``lumitrace serve`` with the standard library only, so that it runs in any
DCC's embedded Python: send scene deltas, read status and results, follow the events.

    from lumitrace.client import Client
    c = Client("http://127.0.0.1:8650")
    answer = c.set("/Luminaire/Materials/ReflectorAluminium",
                   "lumitrace:specularReflectance", 0.8)
    for event in c.events(revision=answer["revision"]):  # this edit's events, not history
        if event.kind == "done" and event.data["revision"] == answer["revision"]:
            print(event.data["judged_error"], event.data["converged"])
            break

``c.events()`` alone replays every event the service keeps (from its start), then follows;
``c.events(since="now")`` follows from now on.

This module imports nothing of lumitrace: copy it where lumitrace is not installed.
"""
from __future__ import annotations

import json
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from typing import Any, Iterator


class ServiceError(Exception):
    """The service refused a request: ``status`` (HTTP), ``message`` and ``problems``
    (a list of ``{"where", "why"}``)."""

    def __init__(self, status: int, message: str, problems: list[dict] | None = None):
        self.status = status
        self.message = message
        self.problems = problems or []
        lines = [f"HTTP {status}: {message}"]
        lines += [f"  {p.get('where', '')}: {p.get('why', '')}" for p in self.problems]
        super().__init__("\n".join(lines))


@dataclass(frozen=True)
class Event:
    """One server-sent event: its id, kind (``iteration``, ``revision``, ``written``,
    ``done``, ``warning``, ``error``, ...) and data."""

    id: int | None
    kind: str
    data: dict[str, Any]


class Client:
    """``url`` of the service (``http://127.0.0.1:8650``); ``token`` when it has one."""

    def __init__(self, url: str = "http://127.0.0.1:8650", token: str | None = None,
                 timeout: float = 30.0):
        self.url = url.rstrip("/")
        self.token = token
        self.timeout = timeout

    def _request(self, method: str, path: str, body: Any = None,
                 headers: dict[str, str] | None = None, timeout: float | None = None):
        data = json.dumps(body).encode() if body is not None else None
        h = {"Accept": "application/json", **(headers or {})}
        if data is not None:
            h["Content-Type"] = "application/json"
        if self.token:
            h["Authorization"] = f"Bearer {self.token}"
        req = urllib.request.Request(self.url + path, data=data, method=method, headers=h)
        try:
            return urllib.request.urlopen(req, timeout=timeout or self.timeout)
        except urllib.error.HTTPError as exc:
            try:
                payload = json.loads(exc.read().decode() or "{}")
            except ValueError:
                payload = {}
            raise ServiceError(exc.code, payload.get("error", exc.reason),
                               payload.get("problems")) from None

    def _json(self, method: str, path: str, body: Any = None) -> dict[str, Any]:
        with self._request(method, path, body) as response:
            return json.loads(response.read().decode())

    # -- reading ------------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        """Revision, photons, error, what is written, the edits layer's path."""
        return self._json("GET", "/status")

    def results(self) -> dict[str, Any]:
        """Paths and figures of the last written result, with its revision."""
        return self._json("GET", "/results")

    def history(self, last_id: int = 0) -> list[Event]:
        """The events after ``last_id`` that the service still keeps, without waiting."""
        data = self._json("GET", f"/events?format=json&last_id={int(last_id)}")
        return [Event(e["id"], e["event"], e["data"]) for e in data["events"]]

    def events(self, last_id: int | None = None, timeout: float | None = None,
               since: str | None = None, revision: int | None = None) -> Iterator[Event]:
        """Follow the event stream: from the oldest event the service keeps, from after
        ``last_id`` (reconnect with the last id seen to resume), from now on
        (``since="now"``), or from the first event of ``revision`` or a later one.
        ``timeout`` bounds the wait for each line (s)."""
        headers = {"Accept": "text/event-stream"}
        query = ""
        if last_id is not None:
            headers["Last-Event-ID"] = str(last_id)
        elif since is not None:
            query = "?since=" + urllib.parse.quote(str(since))
        elif revision is not None:
            query = f"?revision={int(revision)}"
        with self._request("GET", "/events" + query, headers=headers,
                           timeout=timeout) as response:
            fields: dict[str, str] = {}
            for raw in response:
                line = raw.decode("utf-8").rstrip("\r\n")
                if not line:
                    if "data" in fields or "event" in fields:
                        yield Event(int(fields["id"]) if "id" in fields else None,
                                    fields.get("event", "message"),
                                    json.loads(fields.get("data") or "{}"))
                    fields = {}
                elif not line.startswith(":"):
                    key, _, value = line.partition(":")
                    fields[key] = value[1:] if value.startswith(" ") else value

    # -- editing ------------------------------------------------------------------------

    def send(self, deltas: list[dict[str, Any]], base_revision: int | None = None
             ) -> dict[str, Any]:
        """Post a batch of deltas (all applied or none); returns the new revision and the
        effect. Raises :class:`ServiceError` listing every problem."""
        body: dict[str, Any] = {"deltas": list(deltas)}
        if base_revision is not None:
            body["base_revision"] = base_revision
        return self._json("POST", "/deltas", body)

    def set(self, path: str, prop: str, value: Any, type: str | None = None) -> dict[str, Any]:
        """Set one attribute value (``type`` only to create an attribute the prim lacks)."""
        delta = {"op": "set", "path": path, "property": prop, "value": value}
        if type:
            delta["type"] = type
        return self.send([delta])

    def transform(self, path: str, translate=None, rotate=None, scale=None,
                  matrix=None) -> dict[str, Any]:
        """Replace a prim's local transform (stage units, XYZ degrees)."""
        delta: dict[str, Any] = {"op": "transform", "path": path}
        for key, value in (("translate", translate), ("rotate", rotate), ("scale", scale),
                           ("matrix", matrix)):
            if value is not None:
                delta[key] = [list(map(float, r)) if isinstance(r, (list, tuple)) else
                              float(r) for r in value]
        return self.send([delta])

    def bind(self, path: str, material: str) -> dict[str, Any]:
        return self.send([{"op": "bind", "path": path, "material": material}])

    def wait_written(self, revision: int, pictures: bool = False,
                     timeout: float = 120.0) -> Event:
        """Follow events until a result of ``revision`` (or later) is written (with its
        pictures when ``pictures``); returns that event."""
        for event in self.events(revision=revision, timeout=timeout):
            if event.kind == "written" and event.data.get("revision", -1) >= revision \
                    and (event.data.get("pictures") or not pictures):
                return event
        raise ServiceError(0, "the event stream ended before the result was written")
