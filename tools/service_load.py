"""Load and latency of ``lumitrace serve`` on the demo stage, on loopback only.

    python tools/service_load.py [--clients 4] [--deltas 25] [--only load] [--json]

Three measurements, each against a real server process on a free loopback port, on a copy
of ``stages/downlight.usda`` in a temporary folder:

1. latency: from a delta's arrival to the first refreshed result on disk, for a material
   edit and for a flux-only edit, and to the 2% estimated error (median of a few edits);
2. load: N concurrent clients posting deltas and reading status; requests per second,
   latency percentiles, and the proof that no accepted delta was lost (the final edits
   layer holds the value of the highest accepted revision; revisions are 1..N unique);
   then the same beside hostile clients: 200 event streams held open, 8 slow readers of
   /events (4 KiB receive buffers, 64 bytes read a second) and a client posting bodies of
   exactly the size limit (accepted, counted among the deltas that must not be lost) and
   one byte over it (413);
3. events: how many events per second one event stream delivers (events published as
   fast as the service can, read by the stdlib client).
"""
from __future__ import annotations

import argparse
import asyncio
import json
import shutil
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from service_process import Service  # noqa: E402

DEMO = HERE.parent / "stages" / "downlight.usda"
REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
SPEC = "lumitrace:specularReflectance"


def _stage(folder: Path) -> Path:
    path = folder / "downlight.usda"
    shutil.copy(DEMO, path)
    return path


def _wait_event(service: Service, kind: str, revision: int, after_id: int, timeout=120.0,
                **match):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for e in service.client.history(after_id):
            if e.kind == kind and e.data.get("revision") == revision and all(
                    e.data.get(k) == v for k, v in match.items()):
                return e
        time.sleep(0.005)
    raise TimeoutError(f"no {kind} event for revision {revision}")


def _last_id(service: Service) -> int:
    events = service.client.history(0)
    return events[-1].id if events else 0


def measure_latency(folder: Path, repeats: int) -> dict:
    """Seconds from a delta's arrival (the request sent) to the first written result of its
    revision, and to the done event at 2% estimated error."""
    out = {"material_first_write": [], "flux_first_write": [], "material_to_2pct": [],
           "photons_to_2pct": []}
    with Service(_stage(folder), "--target-error", 0.02, "--resolution", 32) as s:
        s.wait_status(lambda st: st["state"] == "done" and st["written_pictures"], 300)
        for i in range(repeats):
            value = 0.9 - 0.05 * i
            last = _last_id(s)
            t0 = time.time()
            rev = s.client.set(REFLECTOR, SPEC, value)["revision"]
            written = _wait_event(s, "written", rev, last)
            done = _wait_event(s, "done", rev, last, timeout=300)
            out["material_first_write"].append(written.data["time"] - t0)
            out["material_to_2pct"].append(done.data["time"] - t0)
            out["photons_to_2pct"].append(done.data["photons"])
            s.wait_status(lambda st: st["written_pictures"] and st["written_revision"] == rev)
            last = _last_id(s)
            t0 = time.time()
            rev = s.client.set("/Luminaire/LED", "lumitrace:luminousFlux",
                               1200.0 + 10 * (i + 1))["revision"]
            written = _wait_event(s, "written", rev, last)
            out["flux_first_write"].append(written.data["time"] - t0)
            s.wait_status(lambda st: st["written_revision"] == rev and st["written_pictures"])
    return {k: statistics.median(v) for k, v in out.items()} | {"repeats": repeats}


#: The hostile clients beside the normal load: event streams held open and read as they
#: come, slow readers of /events, and a client posting bodies at the size limit.
STREAMS = 200
SLOW_READERS = 8
#: Most big bodies the hostile poster sends (each one at the limit, then one over it).
BIG_BODIES = 40
HOUSING = "/Luminaire/Materials/HousingPaint/PreviewSurface"


def measure_load(folder: Path, clients: int, deltas: int, hostile: bool = False) -> dict:
    """N clients, each posting ``deltas`` deltas with a status read after each; with
    ``hostile``, :data:`STREAMS` event streams, :data:`SLOW_READERS` slow readers and a
    poster of bodies at the size limit run beside them the whole time."""
    latencies = {"delta": [], "status": []}
    accepted: list[tuple[int, float]] = []
    failures: list[str] = []
    lock = threading.Lock()
    stage = _stage(folder)
    with Service(stage, "--photons", 200_000, "--resolution", 16, "--quiet") as s:
        def client(k: int) -> None:
            for i in range(deltas):
                value = round(0.05 + 0.9 * (k * deltas + i) / (clients * deltas), 6)
                try:
                    t0 = time.perf_counter()
                    r = s.client.set(REFLECTOR, SPEC, value)
                    t1 = time.perf_counter()
                    s.client.status()
                    t2 = time.perf_counter()
                except Exception as exc:  # counted, the run goes on
                    with lock:
                        failures.append(repr(exc))
                    continue
                with lock:
                    latencies["delta"].append(t1 - t0)
                    latencies["status"].append(t2 - t1)
                    accepted.append((r["revision"], value))
        stop = threading.Event()
        hostiles = _start_hostile(s.url, stop) if hostile else None
        threads = [threading.Thread(target=client, args=(k,)) for k in range(clients)]
        t0 = time.perf_counter()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        wall = time.perf_counter() - t0
        stop.set()
        extra = hostiles.finish() if hostiles else {}
        revisions_all = sorted([r for r, _ in accepted] + extra.get("revisions", []))
        final = s.wait_status(lambda st: st["traced_revision"] == revisions_all[-1]
                              and st["written_revision"] == revisions_all[-1], 300)
        rc, _ = s.stop()
    from pxr import Sdf

    edits = Sdf.Layer.OpenAsAnonymous(str(folder / "downlight.lumitrace-edits.usda"))
    stored = edits.GetAttributeAtPath(f"{REFLECTOR}.{SPEC}").default
    expected = max(accepted)[1]
    lost = int(abs(float(stored) - expected) > 1e-6)
    if extra.get("last_value") is not None:
        paint = edits.GetAttributeAtPath(f"{HOUSING}.inputs:diffuseColor").default
        lost += int(abs(float(paint[0]) - extra["last_value"]) > 1e-6)
    requests = len(latencies["delta"]) + len(latencies["status"])
    return {
        "clients": clients, "deltas_per_client": deltas, "accepted": len(accepted),
        "failures": len(failures), "requests_per_second": requests / wall,
        "delta_ms": _percentiles(latencies["delta"]),
        "status_ms": _percentiles(latencies["status"]),
        "revisions_unique_and_contiguous": revisions_all == list(
            range(1, len(revisions_all) + 1)),
        "final_value_is_last_accepted": lost == 0, "accepted_deltas_lost": lost,
        "final_revision": final["revision"], "exit_status": rc,
        **({"hostile": {k: v for k, v in extra.items() if k != "revisions"}} if hostile
           else {}),
    }


class _Hostile:
    """The hostile clients of :func:`measure_load`, each a thread with a bounded loop."""

    def __init__(self, url: str, stop: threading.Event):
        from urllib.parse import urlsplit

        parts = urlsplit(url)
        self.address = (parts.hostname, parts.port)
        self.url = url.rstrip("/")
        self.stop = stop
        self.stats = {"streams_open": 0, "stream_bytes": 0, "slow_bytes": 0,
                      "big_accepted": 0, "big_413": 0, "big_other": [], "revisions": [],
                      "last_value": None}
        self.threads = [threading.Thread(target=self._streams, daemon=True),
                        threading.Thread(target=self._slow, daemon=True),
                        threading.Thread(target=self._big, daemon=True)]
        for t in self.threads:
            t.start()

    def _open_stream(self, rcvbuf: int | None = None):
        import socket

        sock = socket.socket()
        if rcvbuf:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        sock.connect(self.address)
        host = f"{self.address[0]}:{self.address[1]}".encode()
        sock.sendall(b"GET /events HTTP/1.1\r\nHost: " + host + b"\r\nAccept: "
                     b"text/event-stream\r\n\r\n")
        return sock

    def _streams(self) -> None:
        """:data:`STREAMS` event streams, all read as the events come."""
        import selectors

        sel = selectors.DefaultSelector()
        socks = [self._open_stream() for _ in range(STREAMS)]
        self.stats["streams_open"] = len(socks)
        for sock in socks:
            sock.setblocking(False)
            sel.register(sock, selectors.EVENT_READ)
        start = time.monotonic()
        deadline = start + 600
        # a short load can end before the streams are served: read on until they have
        # their first bytes (at most 10 s), so every stream was really held open
        while (not self.stop.is_set() or (not self.stats["stream_bytes"]
                                          and time.monotonic() < start + 10.0)) \
                and time.monotonic() < deadline:
            for key, _ in sel.select(0.2):
                try:
                    self.stats["stream_bytes"] += len(key.fileobj.recv(65536))
                except BlockingIOError:
                    pass
        for sock in socks:
            sock.close()

    def _slow(self) -> None:
        """:data:`SLOW_READERS` streams with a 4 KiB receive buffer read 64 bytes a
        second each: the service's writes to them back up."""
        socks = [self._open_stream(rcvbuf=4096) for _ in range(SLOW_READERS)]
        deadline = time.monotonic() + 600
        while not self.stop.wait(1.0) and time.monotonic() < deadline:
            for sock in socks:
                sock.settimeout(0.01)
                try:
                    self.stats["slow_bytes"] += len(sock.recv(64))
                except OSError:
                    pass
        for sock in socks:
            sock.close()

    def _big(self) -> None:
        """Bodies at the size limit (a delta padded with spaces to exactly the limit:
        accepted, and counted as any accepted delta) and one byte over it (413)."""
        import urllib.error
        import urllib.request

        from lumitrace.serve.app import MAX_BODY_BYTES

        for i in range(BIG_BODIES):
            if i and self.stop.is_set():  # the first pair is sent however short the load
                break
            value = round(0.1 + 0.8 * i / BIG_BODIES, 6)
            body = json.dumps({"deltas": [{"op": "set", "path": HOUSING,
                                           "property": "inputs:diffuseColor",
                                           "value": [value] * 3}]}).encode()
            for size, want in ((MAX_BODY_BYTES, 200), (MAX_BODY_BYTES + 1, 413)):
                req = urllib.request.Request(self.url + "/deltas", method="POST",
                                             data=body + b" " * (size - len(body)),
                                             headers={"Content-Type": "application/json"})
                try:
                    with urllib.request.urlopen(req, timeout=60) as r:
                        code, answer = r.status, json.loads(r.read())
                except urllib.error.HTTPError as exc:
                    code, answer = exc.code, {}
                except OSError as exc:  # the server may close on an oversized body
                    code, answer = (413 if want == 413 else repr(exc)), {}
                if code == 200:
                    self.stats["big_accepted"] += 1
                    self.stats["revisions"].append(answer["revision"])
                    if answer["revision"] == max(self.stats["revisions"]):
                        self.stats["last_value"] = value
                elif code == 413:
                    self.stats["big_413"] += 1
                else:
                    self.stats["big_other"].append(code)

    def finish(self) -> dict:
        for t in self.threads:
            t.join(120)
        return dict(self.stats)


def _start_hostile(url: str, stop: threading.Event) -> _Hostile:
    return _Hostile(url, stop)


def _percentiles(values: list[float]) -> dict:
    if not values:
        return {}
    q = statistics.quantiles(sorted(values), n=100, method="inclusive")
    return {"p50": 1e3 * q[49], "p90": 1e3 * q[89], "p99": 1e3 * q[98],
            "max": 1e3 * max(values)}


def measure_events(count: int) -> dict:
    """Events per second one stream delivers: a real aiohttp server on loopback with the
    service's event log and stream handler, events published from a thread as fast as
    possible, read and parsed by the stdlib client."""
    from aiohttp import web

    from lumitrace.client import Client
    from lumitrace.serve.app import make_app
    from lumitrace.serve.events import EventLog

    events = EventLog(history=count + 16)
    result: dict = {}

    async def main():
        events.bind(asyncio.get_running_loop())
        runner = web.AppRunner(make_app(None, None, events, viewer=False), access_log=None)
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        host, port = runner.addresses[0][:2]
        client = Client(f"http://{host}:{port}")

        def read():
            n, t0 = 0, time.perf_counter()
            for e in client.events(last_id=0, timeout=30):
                n += 1
                if e.id >= count:
                    break
            result["seconds"] = time.perf_counter() - t0
            result["received"] = n

        def publish():
            for i in range(count):
                events.publish("iteration", revision=1, iteration=i, photons=i * 1000,
                               relative_error=0.05)
        reader = threading.Thread(target=read)
        reader.start()
        await asyncio.get_running_loop().run_in_executor(None, publish)
        await asyncio.get_running_loop().run_in_executor(None, reader.join)
        await runner.cleanup()
    asyncio.run(main())
    return {"events": count, "received": result["received"],
            "events_per_second": result["received"] / result["seconds"]}


def _print_load(name: str, load: dict) -> None:
    """The lines of one load run."""
    print(f"{name}: {load['clients']} clients x {load['deltas_per_client']} deltas "
          "(+ a status read each)")
    h = load.get("hostile")
    if h:
        print(f"  beside {h['streams_open']} event streams ({h['stream_bytes']:,} bytes read), "
              f"{SLOW_READERS} slow readers ({h['slow_bytes']:,} bytes read), "
              f"{h['big_accepted']} bodies at the limit accepted, {h['big_413']} over it "
              f"refused (413){', others: ' + str(h['big_other']) if h['big_other'] else ''}")
    print(f"  requests per second  {load['requests_per_second']:.1f}")
    for k in ("delta_ms", "status_ms"):
        q = load[k]
        print(f"  {k[:-3]:6s} latency ms   p50 {q['p50']:.1f}  p90 {q['p90']:.1f}  "
              f"p99 {q['p99']:.1f}  max {q['max']:.1f}")
    print(f"  accepted {load['accepted']}, failed {load['failures']}; revisions 1..N unique: "
          f"{load['revisions_unique_and_contiguous']}; accepted deltas lost: "
          f"{load['accepted_deltas_lost']}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--clients", type=int, default=4)
    p.add_argument("--deltas", type=int, default=25, help="deltas per client")
    p.add_argument("--repeats", type=int, default=3, help="edits timed for the latencies")
    p.add_argument("--events", type=int, default=20_000)
    p.add_argument("--only", choices=("latency", "load", "events"), default=None)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if not (1 <= args.clients <= 32 and 1 <= args.deltas <= 500 and 1 <= args.repeats <= 10):
        p.error("bounded: 1-32 clients, 1-500 deltas each, 1-10 repeats")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "a").mkdir()
        (tmp / "b").mkdir()
        (tmp / "c").mkdir()
        runs = {"latency_s": lambda: measure_latency(tmp / "a", args.repeats),
                "load": lambda: measure_load(tmp / "b", args.clients, args.deltas),
                "load_hostile": lambda: measure_load(tmp / "c", args.clients, args.deltas,
                                                     hostile=True),
                "event_stream": lambda: measure_events(args.events)}
        report = {k: f() for k, f in runs.items()
                  if args.only is None or k.startswith(args.only[:4])}
    loads = [report[k] for k in ("load", "load_hostile") if k in report]
    sound = all(run["failures"] == 0 and run["revisions_unique_and_contiguous"]
                and run["accepted_deltas_lost"] == 0 for run in loads)
    if args.only or args.json:
        print(json.dumps(report, indent=2))
        return 0 if sound else 1
    lat, load, ev = report["latency_s"], report["load"], report["event_stream"]
    print(f"latency (median of {lat['repeats']} edits, demo stage, 2 cores)")
    print(f"  material edit -> first refreshed result on disk  {1e3 * lat['material_first_write']:8.0f} ms")
    print(f"  flux-only edit -> refreshed result on disk        {1e3 * lat['flux_first_write']:8.0f} ms")
    print(f"  material edit -> 2% estimated error, written      {lat['material_to_2pct']:8.2f} s "
          f"({lat['photons_to_2pct']:,.0f} photons)")
    hostile = report["load_hostile"]
    for name, run in (("load", load), ("load beside hostile clients", hostile)):
        _print_load(name, run)
    print(f"event stream: {ev['received']:,} events at {ev['events_per_second']:,.0f} events/s")
    ok = all(run["failures"] == 0 and run["revisions_unique_and_contiguous"]
             and run["accepted_deltas_lost"] == 0 for run in (load, hostile)) \
        and ev["received"] == ev["events"]
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
