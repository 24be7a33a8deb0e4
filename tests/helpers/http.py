"""JSON over HTTP as a client of the service sends it, for tests that read a refusal's
status and body as well as an answer's."""
from __future__ import annotations

import json
import urllib.error
import urllib.request


def call_json(url: str, body: dict | None = None) -> tuple[int, dict]:
    """GET ``url`` (``body`` None) or POST ``body`` as JSON: (status, the JSON answer),
    4xx and 5xx answers included."""
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data, method="GET" if body is None else "POST",
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())
