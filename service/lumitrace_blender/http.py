"""Talk to ``lumitrace serve`` over HTTP with the standard library (urllib): JSON bodies,
no Origin header, the bearer token where the service has one. (``lumitrace.client`` is
stdlib-only too, but importing it imports the ``lumitrace`` package, which Blender's
Python does not have.)"""
from __future__ import annotations

import json
import urllib.error
import urllib.request


class ServiceError(Exception):
    """The service refused a request (``status``: HTTP status, 0 when unreachable), with
    its message and the problems it listed (``{"where", "why"}`` each)."""

    def __init__(self, status: int, message: str, problems: list | None = None):
        self.status, self.message, self.problems = status, message, problems or []
        lines = [f"HTTP {status}: {message}" if status else message]
        lines += [f"  {p.get('where', '')}: {p.get('why', '')}" for p in self.problems]
        super().__init__("\n".join(lines))


class Service:
    """A running service at ``url`` (``http://127.0.0.1:8650``)."""

    def __init__(self, url: str, token: str | None = None, timeout: float = 30.0):
        if not url.startswith(("http://", "https://")):
            raise ValueError(f"the service URL must start with http:// or https://: {url!r}")
        self.url = url.rstrip("/")
        self.token = token or None
        self.timeout = timeout

    def _open(self, method: str, path: str, body=None, headers=None, timeout=None):
        data = json.dumps(body).encode() if body is not None else None
        h = {"Accept": "application/json", **(headers or {})}
        if data is not None:
            h["Content-Type"] = "application/json"
        if self.token:
            h["Authorization"] = f"Bearer {self.token}"
        request = urllib.request.Request(self.url + path, data=data, method=method, headers=h)
        try:
            return urllib.request.urlopen(request, timeout=timeout or self.timeout)
        except urllib.error.HTTPError as exc:
            try:
                payload = json.loads(exc.read().decode() or "{}")
            except ValueError:
                payload = {}
            raise ServiceError(exc.code, payload.get("error", str(exc.reason)),
                               payload.get("problems")) from None
        except (urllib.error.URLError, OSError) as exc:
            reason = getattr(exc, "reason", exc)
            raise ServiceError(0, f"cannot reach {self.url}: {reason}") from None

    def json(self, method: str, path: str, body=None) -> dict:
        with self._open(method, path, body) as response:
            return json.loads(response.read().decode())

    def status(self) -> dict:
        return self.json("GET", "/status")

    def results(self) -> dict:
        return self.json("GET", "/results")

    def send(self, deltas: list[dict]) -> dict:
        """Post one batch of deltas (applied all together or not at all)."""
        return self.json("POST", "/deltas", {"deltas": list(deltas)})

    def history(self, last_id: int = 0) -> list[dict]:
        """The kept events after ``last_id`` (``{"id", "event", "data"}`` each)."""
        return self.json("GET", f"/events?format=json&last_id={int(last_id)}")["events"]
