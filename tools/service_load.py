"""Load and latency of ``lumitrace serve`` on the demo stage, on loopback only.

    python tools/service_load.py [--clients 4] [--deltas 25] [--seconds 60] [--json]

Three measurements, each against a real server process on a free loopback port, on a copy
of ``stages/downlight.usda`` in a temporary folder:

1. latency: from a delta's arrival to the first refreshed result on disk, for a material
   edit and for a flux-only edit, and to the 2% estimated error (median of a few edits);
2. load: N concurrent clients posting deltas and reading status; requests per second,
   latency percentiles, and the proof that no accepted delta was lost (the final edits
   layer holds the value of the highest accepted revision; revisions are 1..N unique);
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


def measure_load(folder: Path, clients: int, deltas: int) -> dict:
    """N clients, each posting ``deltas`` deltas with a status read after each."""
    latencies = {"delta": [], "status": []}
    accepted: list[tuple[int, float]] = []
    failures: list[str] = []
    lock = threading.Lock()
    stage = _stage(folder)
    with Service(stage, "--photons", 200_000, "--resolution", 16) as s:
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
        threads = [threading.Thread(target=client, args=(k,)) for k in range(clients)]
        t0 = time.perf_counter()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        wall = time.perf_counter() - t0
        final = s.wait_status(lambda st: st["traced_revision"] == max(accepted)[0]
                              and st["written_revision"] == max(accepted)[0], 300)
        rc, _ = s.stop()
    from pxr import Sdf

    edits = Sdf.Layer.OpenAsAnonymous(str(folder / "downlight.lumitrace-edits.usda"))
    stored = edits.GetAttributeAtPath(f"{REFLECTOR}.{SPEC}").default
    revisions = sorted(r for r, _ in accepted)
    expected = max(accepted)[1]
    requests = len(latencies["delta"]) + len(latencies["status"])
    return {
        "clients": clients, "deltas_per_client": deltas, "accepted": len(accepted),
        "failures": len(failures), "requests_per_second": requests / wall,
        "delta_ms": _percentiles(latencies["delta"]),
        "status_ms": _percentiles(latencies["status"]),
        "revisions_unique_and_contiguous": revisions == list(range(1, len(accepted) + 1)),
        "final_value_is_last_accepted": abs(float(stored) - expected) < 1e-6,
        "final_revision": final["revision"], "exit_status": rc,
    }


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
        runner = web.AppRunner(make_app(None, None, events), access_log=None)
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
        runs = {"latency_s": lambda: measure_latency(tmp / "a", args.repeats),
                "load": lambda: measure_load(tmp / "b", args.clients, args.deltas),
                "event_stream": lambda: measure_events(args.events)}
        report = {k: f() for k, f in runs.items()
                  if args.only is None or k.startswith(args.only[:4])}
    if args.only or args.json:
        print(json.dumps(report, indent=2))
        return 0
    lat, load, ev = report["latency_s"], report["load"], report["event_stream"]
    print(f"latency (median of {lat['repeats']} edits, demo stage, 2 cores)")
    print(f"  material edit -> first refreshed result on disk  {1e3 * lat['material_first_write']:8.0f} ms")
    print(f"  flux-only edit -> refreshed result on disk        {1e3 * lat['flux_first_write']:8.0f} ms")
    print(f"  material edit -> 2% estimated error, written      {lat['material_to_2pct']:8.2f} s "
          f"({lat['photons_to_2pct']:,.0f} photons)")
    print(f"load: {load['clients']} clients x {load['deltas_per_client']} deltas (+ a status read each)")
    print(f"  requests per second  {load['requests_per_second']:.1f}")
    for k in ("delta_ms", "status_ms"):
        q = load[k]
        print(f"  {k[:-3]:6s} latency ms   p50 {q['p50']:.1f}  p90 {q['p90']:.1f}  "
              f"p99 {q['p99']:.1f}  max {q['max']:.1f}")
    print(f"  accepted {load['accepted']}, failed {load['failures']}; revisions 1..N unique: "
          f"{load['revisions_unique_and_contiguous']}; final stage value = last accepted: "
          f"{load['final_value_is_last_accepted']}")
    print(f"event stream: {ev['received']:,} events at {ev['events_per_second']:,.0f} events/s")
    ok = (load["failures"] == 0 and load["revisions_unique_and_contiguous"]
          and load["final_value_is_last_accepted"] and ev["received"] == ev["events"])
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
