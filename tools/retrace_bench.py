"""Selective retracing against a full retrace of the same photons, per change class.

    python tools/retrace_bench.py [--photons 1000000] [--stages downlight louvre] [--json]

For each stage (``stages/downlight.usda``, ``stages/louvre.usda``) the photons are traced
once with their records; then each kind of edit is made on a copy of the stage and the
result refreshed two ways, in the same run: selectively (the photons the edit can change,
retraced with the same indices) and by a full retrace of all the photons in the same frame.
Both maps must be equal, count for count. Printed per edit: the fraction of photons
retraced, both times and their ratio; per stage: the record memory per million photons.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade

from lumitrace.delta.effect import classify
from lumitrace.run.incremental import retrace, select
from lumitrace.run.session import Refinement, run
from lumitrace.run.settings import TraceSettings
from lumitrace.stage.reader import read_stage
from lumitrace.trace.prepared import TracingFrame, prepare
from lumitrace.trace.records import RECORD_BYTES
from lumitrace.trace.tracer import trace_batch

ROOT = Path(__file__).resolve().parents[1]


def _set(path: str, prop: str, value):
    def edit(stage):
        stage.GetPrimAtPath(path).GetAttribute(prop).Set(value)
    return edit


def _move(path: str, offset):
    def edit(stage):
        xf = UsdGeom.Xformable(stage.GetPrimAtPath(path))
        xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble, "benchEdit").Set(Gf.Vec3d(*offset))
    return edit


def _bind(path: str, material: str):
    def edit(stage):
        UsdShade.MaterialBindingAPI.Apply(stage.GetPrimAtPath(path)).Bind(
            UsdShade.Material(stage.GetPrimAtPath(material)))
    return edit


def _deactivate(path: str):
    def edit(stage):
        stage.GetPrimAtPath(path).SetActive(False)
    return edit


def _display(path: str):
    def edit(stage):
        UsdGeom.Gprim(stage.GetPrimAtPath(path)).CreateDisplayColorAttr([Gf.Vec3f(1, 0, 0)])
    return edit


EDITS = {
    "downlight": [
        ("none: display colour of the housing", _display("/Luminaire/Housing")),
        ("flux: the LED's flux", _set("/Luminaire/LED", "lumitrace:luminousFlux", 1500.0)),
        ("material: the reflector's specular reflectance",
         _set("/Luminaire/Materials/ReflectorAluminium", "lumitrace:specularReflectance", 0.8)),
        ("material: the housing's paint", _bind("/Luminaire/Housing",
                                                "/Luminaire/Materials/BoardWhite")),
        ("geometry: the diffuser 1 mm lower", _move("/Luminaire/Diffuser", (0, 0, -1.0))),
        ("emitter: the LED 1 mm sideways", _move("/Luminaire/LED", (1.0, 0, 0))),
    ],
    "louvre": [
        ("none: display colour of a blade", _display("/Luminaire/Louvre/Blade_10")),
        ("flux: one LED's flux", _set("/Luminaire/LEDs/LED_1_3", "lumitrace:luminousFlux",
                                      150.0)),
        ("material: one blade rebound (mirror)", _bind("/Luminaire/Louvre/Blade_10",
                                                       "/Luminaire/Materials/SideReflector")),
        ("material: one side reflector's mirror",
         _bind("/Luminaire/SideA", "/Luminaire/Materials/LouvreSpecular")),
        ("geometry: one blade 2 mm sideways", _move("/Luminaire/Louvre/Blade_10",
                                                    (2.0, 0, 0))),
        ("topology: one blade removed", _deactivate("/Luminaire/Louvre/Blade_40")),
        ("emitter: one LED 1 mm sideways", _move("/Luminaire/LEDs/LED_1_3", (1.0, 0, 0))),
        ("material: all blades' finish (shared material)",
         _set("/Luminaire/Materials/LouvreSpecular", "lumitrace:roughness", 0.2)),
    ],
}


def bench_stage(name: str, photons: int, threads: int) -> dict:
    settings = TraceSettings(photons=photons, resolution=64, seed=1, threads=threads,
                             workers="threads")
    rows = []
    with tempfile.TemporaryDirectory() as tmp, \
            ThreadPoolExecutor(max_workers=threads) as pool:
        src = Path(tmp) / f"{name}.usda"
        shutil.copy(ROOT / "stages" / f"{name}.usda", src)
        scene = read_stage(src)
        frame = TracingFrame.of(scene)
        base = Refinement(scene, settings, records_cap=1 << 34)
        ps = prepare(scene, frame)
        t0 = time.perf_counter()
        while True:
            jobs = base.next_jobs()
            if not jobs:
                break
            base.add_round(pool.map(lambda j: trace_batch(ps, j, records=True), jobs))
        first = time.perf_counter() - t0
        record_bytes = sum(r.nbytes for r in base.records)
        snapshot = (base.accumulator.snapshot(), [r.take(np.arange(len(r)))
                                                   for r in base.records])
        for label, edit in EDITS[name]:
            work = Path(tmp) / f"edit_{len(rows)}.usda"
            shutil.copy(src, work)
            stage = Usd.Stage.Open(str(work))
            edit(stage)
            stage.GetRootLayer().Save()
            Sdf.Layer.Find(str(work)).Reload(force=True)
            new = read_stage(work)
            r = Refinement(scene, settings, records_cap=1 << 34)
            r.accumulator, r.records = snapshot[0].snapshot(), [x.take(np.arange(len(x)))
                                                                for x in snapshot[1]]
            r.done, r.iteration = list(base.done), base.iteration
            kind = classify(scene, new).kind
            before = prepare(scene, frame)  # the luminaire as it was, as the service holds it
            t0 = time.perf_counter()
            prepare_s, rebuilt = 0.0, 0
            if kind == "flux":
                r.rescale(new)
                if r.estimate_current() is None:  # none to scale: the map the preview shows
                    r.reestimate()
                n, exact = 0, None
            else:
                sel = select(r.records, scene, new, frame)
                if sel.restart:
                    raise SystemExit(f"{name}: {label}: restart: {sel.restart}")
                t1 = time.perf_counter()
                ps_new = prepare(new, frame, previous=before)  # the edited parts' Embree
                prepare_s = time.perf_counter() - t1
                rebuilt = len(getattr(ps_new.embree, "rebuilt", ()))
                retrace(r, new, sel, lambda w: pool.map(
                    lambda item: trace_batch(ps_new, item[0], photons=item[1], records=True),
                    w), settings.batch_size)
                n = sel.photons
            incremental = time.perf_counter() - t0
            t0 = time.perf_counter()
            fresh = run(new, settings, frame=frame)
            full = time.perf_counter() - t0
            if kind != "flux":
                exact = bool(np.array_equal(r.accumulator.counts(), fresh.accumulator.counts()))
            rows.append({"edit": label, "kind": kind, "retraced": n / photons,
                         "incremental_s": incremental, "full_s": full,
                         "speedup": full / max(incremental, 1e-9), "exact": exact,
                         "prepare_s": prepare_s,
                         "rebuilt_parts": rebuilt,
                         "error": float(r.estimate.error)})
    return {"stage": name, "photons": photons, "first_trace_s": first,
            "record_mb_per_million": record_bytes / photons,
            "record_bytes_per_photon": RECORD_BYTES, "edits": rows}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--photons", type=int, default=1_000_000)
    p.add_argument("--stages", nargs="+", default=["downlight", "louvre"],
                   choices=sorted(EDITS))
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    warnings.simplefilter("ignore")
    results = [bench_stage(s, args.photons, args.threads) for s in args.stages]
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    ok = True
    for res in results:
        print(f"{res['stage']}: {res['photons']:,} photons traced in {res['first_trace_s']:.1f} s; "
              f"records {res['record_mb_per_million']:.0f} MB per million photons")
        print(f"  {'edit':52s} {'kind':9s} {'retraced':>8s} {'selective':>9s} {'full':>7s} "
              f"{'ratio':>6s}  exact  error   Embree parts rebuilt")
        for e in res["edits"]:
            ok &= e["exact"] is not False
            print(f"  {e['edit']:52s} {e['kind']:9s} {e['retraced']:8.1%} "
                  f"{e['incremental_s']:8.2f}s {e['full_s']:6.2f}s {e['speedup']:5.1f}x  "
                  f"{'-' if e['exact'] is None else 'yes' if e['exact'] else 'NO'}    "
                  f"{e['error']:.2%}   {e['rebuilt_parts']}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
