"""The live loop's latencies against a real ``lumitrace serve``: from a delta's arrival to
the first refreshed preview a client can read, and to the cheap outputs on disk.

    python tools/live_loop_bench.py [--stage stages/downlight.usda] [--edits 20]
                                    [--client poll|page] [--pause S] [--json]

The service traces the stage (a copy) until it is converged; then, ``--edits`` times each,
a material edit (the reflector's specular reflectance) and a flux-only edit (the source's
flux) are sent, each once the previous one is written. Timed on the client, from the send:
``accepted``, the service's answer to the delta (applied, the stage read again);
``preview``, the first ``/preview`` frame that carries the new revision: with ``--client
poll`` fetched every 2 ms (a client that loads the service as hard as it can), with
``--client page`` fetched as the live view's page fetches it, at each event of the
revision (its ``revision``, ``iteration``, ``retrace``, ``written`` and ``done``);
``written``, the ``written`` event of the revision (the IES, LDT, EXR and result layer on
disk). ``--pause S``: each edit S seconds after the last one was sent, its revision done
first, as a designer pausing between edits (past the service's 1 s quiet, an edit lands
while the last one's pictures are drawn). Printed: median and 90th percentile of each, in
ms.
"""
from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from service_process import Service  # noqa: E402

from lumitrace.serve.viewer import read_frame  # noqa: E402

ROOT = HERE.parent
REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
SOURCE = "/Luminaire/LED"


def _preview_revision(url: str) -> int | None:
    try:
        with urllib.request.urlopen(url + "preview", timeout=5) as r:
            if r.status == 204:  # no frame yet (a restarted trace before its first round)
                return None
            return read_frame(r.read())[0].get("revision")
    except OSError:
        return None


#: The events the live view's page fetches a preview at.
PAGE_EVENTS = ("revision", "iteration", "retrace", "written", "done")


def _watch(service: Service, seen: dict, arrived: threading.Condition,
           stop: threading.Event) -> None:
    """Record the arrival time of every ``written`` event by revision (``seen``), and
    count the events the page fetches at (``seen["page"]``: the last revision of one)."""
    for event in service.client.events(timeout=600):
        if stop.is_set():
            return
        if event.kind == "written":
            seen.setdefault(event.data.get("revision"), time.perf_counter())
        if event.kind in PAGE_EVENTS:
            with arrived:
                seen["page"] = (seen.get("page", (0, None))[0] + 1,
                                event.data.get("revision"))
                arrived.notify_all()


def _await_preview(url: str, revision: int, client: str, seen: dict,
                   arrived: threading.Condition) -> None:
    """Until a ``/preview`` frame carries ``revision``: fetched every 2 ms (``poll``) or
    at each event the page fetches at (``page``)."""
    count = -1
    while (_preview_revision(url) or 0) < revision:
        if client == "poll":
            time.sleep(0.002)
            continue
        with arrived:  # the next event (one may have come while fetching: fetch again)
            arrived.wait_for(lambda: seen.get("page", (0, None))[0] != count, timeout=5)
            count = seen.get("page", (0, None))[0]


def _percentile(values: list[float], q: float) -> float:
    v = sorted(values)
    return v[min(len(v) - 1, int(round(q * (len(v) - 1))))]


def measure(stage: Path, edits: int, client: str = "poll", pause: float = 0.0) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / stage.name
        shutil.copy(stage, copy)
        service = Service(copy, "--out", Path(tmp) / "out", "--no-sublayer", "--quiet",
                          "--target-error", "0.02")
        seen: dict = {}
        stop, arrived = threading.Event(), threading.Condition()
        threading.Thread(target=_watch, args=(service, seen, arrived, stop),
                         daemon=True).start()
        try:
            service.wait_status(lambda s: s.get("state") == "done", timeout=300)
            out = {}
            for kind in ("material", "flux"):
                preview, written, accepted = [], [], []
                for k in range(edits):
                    if kind == "material":
                        delta = {"op": "set", "path": REFLECTOR,
                                 "property": "lumitrace:specularReflectance",
                                 "value": 0.80 + 0.005 * (k % 20)}
                    else:
                        delta = {"op": "set", "path": SOURCE,
                                 "property": "lumitrace:luminousFlux",
                                 "value": 1100.0 + 5.0 * k}
                    t0 = time.perf_counter()
                    revision = service.client.send([delta])["revision"]
                    accepted.append(1000.0 * (time.perf_counter() - t0))
                    _await_preview(service.url, revision, client, seen, arrived)
                    preview.append(1000.0 * (time.perf_counter() - t0))
                    deadline = time.monotonic() + 60
                    while revision not in seen and time.monotonic() < deadline:
                        time.sleep(0.002)
                    written.append(1000.0 * (seen.get(revision, time.perf_counter()) - t0))
                    service.wait_status(lambda s: s.get("state") in (
                        ("done",) if pause else ("done", "tracing")))
                    time.sleep(max(0.0, pause - (time.perf_counter() - t0)))
                out[kind] = {name: {"median_ms": statistics.median(v),
                                    "p90_ms": _percentile(v, 0.9)}
                             for name, v in (("accepted", accepted), ("preview", preview),
                                             ("written", written))}
            return out
        finally:
            stop.set()
            service.stop()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--stage", type=Path, default=ROOT / "stages" / "downlight.usda")
    p.add_argument("--edits", type=int, default=20)
    p.add_argument("--json", action="store_true")
    p.add_argument("--client", choices=("poll", "page"), default="poll")
    p.add_argument("--pause", type=float, default=0.0,
                   help="seconds from one edit's send to the next's, each done first")
    a = p.parse_args(argv)
    result = measure(a.stage, a.edits, a.client, a.pause)
    if a.json:
        print(json.dumps(result, indent=1))
    else:
        for kind, rows in result.items():
            print(f"{kind} edit: " + "; ".join(
                f"to the {name} median {r['median_ms']:.0f} ms, 90th percentile "
                f"{r['p90_ms']:.0f} ms" for name, r in rows.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
