"""What an edit of one part costs Embree's structure: a luminaire of one large part (a finely
tessellated reflector) and one small one (a baffle), built one-level and two-level (each
part its own scene, placed by its transform) in one run.

    python tools/part_edit_bench.py [--triangles 1000000] [--repeats 3] [--json]

Timed per structure, medians of ``--repeats``: the first build (``prepare``), moving the
small part and moving the large one by 1 mm, as a stage edit of its transform gives them
(``prepare(..., previous=...)``: one level rebuilds the moved part's triangles, two levels
place its structure anew), and casting the same 200,000 rays the tracer sends (photons of
the luminaire's light, recorded on the first bounces), with the hits the two structures
disagree on.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
import sys
import time

import numpy as np

from lumitrace.scene import Emitter, Material, PartFrame, Scene
from lumitrace.trace import embree
from lumitrace.trace.job import BatchJob
from lumitrace.trace.prepared import prepare
from lumitrace.trace.tracer import trace_batch


def _cone(n_around: int, n_down: int, r0: float, r1: float, depth: float) -> np.ndarray:
    """A reflector cone (2 * n_around * n_down triangles, facing in) from radius ``r0`` at
    z = 0 to ``r1`` at z = -``depth`` (m)."""
    a = np.linspace(0.0, 2.0 * math.pi, n_around + 1)
    z = np.linspace(0.0, -depth, n_down + 1)
    r = np.linspace(r0, r1, n_down + 1)
    p = np.stack([r[:, None] * np.cos(a)[None], r[:, None] * np.sin(a)[None],
                  np.broadcast_to(z[:, None], (n_down + 1, n_around + 1))], axis=-1)
    q00, q01, q10, q11 = p[:-1, :-1], p[:-1, 1:], p[1:, :-1], p[1:, 1:]
    return np.concatenate([np.stack([q00, q10, q11], -2).reshape(-1, 3, 3),
                           np.stack([q00, q11, q01], -2).reshape(-1, 3, 3)])


def luminaire(triangles: int) -> Scene:
    """A downlight: a glossy reflector of about ``triangles`` triangles around a disk LED,
    and a small white baffle ring below it."""
    n_down = max(2, int(math.sqrt(triangles / 8)))
    reflector = _cone(4 * n_down, n_down, 0.02, 0.06, 0.05)
    baffle = _cone(64, 2, 0.061, 0.063, 0.004)
    # each part in its own space (float32, as a stage's points are), placed by its frame
    frames = tuple(PartFrame(np.ascontiguousarray(t, np.float32), np.eye(3),
                             np.array([0.0, 0.0, z])) for t, z in ((reflector, 0.0),
                                                                   (baffle, -0.05)))
    tri = np.concatenate([f.local.astype(np.float64) @ f.linear + f.offset for f in frames])
    part = np.r_[np.zeros(len(reflector), np.int32), np.ones(len(baffle), np.int32)]
    materials = (Material("/Reflector", "glossy", specular_reflectance=0.9, roughness=0.1),
                 Material("/Baffle", "diffuse", reflectance=0.8))
    led = Emitter(path="/Led", kind="disk", flux=1000.0, to_world=np.eye(4), radius=0.01)
    return Scene(tri, part.copy(), part, materials, ("/Reflector", "/Baffle"), (led,),
                 part_frames=frames)


def _moved(scene: Scene, part: int, dz: float) -> Scene:
    """``scene`` with ``part`` moved ``dz`` (m) along z, as the stage reader reads a new
    translation of it: its own triangles the same, its frame's offset and world ones new."""
    frames = list(scene.part_frames)
    f = frames[part]
    frames[part] = dataclasses.replace(f, offset=f.offset + (0.0, 0.0, dz))
    tri = np.array(scene.triangles, np.float64)
    tri[np.asarray(scene.part_index) == part] = \
        frames[part].local.astype(np.float64) @ f.linear + frames[part].offset
    return dataclasses.replace(scene, triangles=tri, part_frames=tuple(frames))


def measure(scene: Scene, two_level: bool, rays) -> dict:
    """Build, the two edits and the rays' cast, in seconds, for one structure."""
    embree.TWO_LEVEL_TRIANGLES = 0 if two_level else 1 << 62
    baffle_moved = _moved(scene, 1, -0.001)
    both_moved = _moved(baffle_moved, 0, -0.001)
    t0 = time.perf_counter()
    ps = prepare(scene)
    t1 = time.perf_counter()
    small = prepare(baffle_moved, ps.frame, previous=ps)
    t2 = time.perf_counter()
    edits = [(small.embree.rebuilt, small.embree.moved)]
    large = prepare(both_moved, ps.frame, previous=small)
    t3 = time.perf_counter()
    edits.append((large.embree.rebuilt, large.embree.moved))
    # one level rebuilds the moved part; two levels place it anew
    assert edits == ([([], [1]), ([], [0])] if two_level else [([1], []), ([0], [])]), edits
    fresh = prepare(scene, ps.frame)
    o, d = rays
    fresh.intersect(o, d)
    t4 = time.perf_counter()
    hits = fresh.intersect(o, d)
    t5 = time.perf_counter()
    assert large.embree.two_level == two_level
    return {"build_s": t1 - t0, "move_small_s": t2 - t1, "move_large_s": t3 - t2,
            "cast_s": t5 - t4, "prim": hits["primID"].copy()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--triangles", type=float, default=1e6)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if embree.library() is None:
        print("Embree's library is not found beside embreex: nothing to compare")
        return 1
    scene = luminaire(int(args.triangles))
    ps = prepare(scene)
    recorded = trace_batch(ps, BatchJob(0, 0, 40000, 1, 8), record_rays=True).rays
    o = np.concatenate([r[0] for r in recorded])[:200_000]
    d = np.concatenate([r[1] for r in recorded])[:200_000]
    saved = embree.TWO_LEVEL_TRIANGLES
    runs = {"one level": [], "two levels": []}
    try:
        for _ in range(args.repeats):  # interleaved
            for name in runs:
                runs[name].append(measure(scene, name == "two levels", (o, d)))
    finally:
        embree.TWO_LEVEL_TRIANGLES = saved
    keys = ("build_s", "move_small_s", "move_large_s", "cast_s")
    out = {name: {k: statistics.median(r[k] for r in rs) for k in keys}
           for name, rs in runs.items()}
    out["triangles"] = len(scene.triangles)
    out["rays"] = len(o)
    out["hits_that_differ"] = int((runs["one level"][0]["prim"]
                                   != runs["two levels"][0]["prim"]).sum())
    for k in keys:
        out[f"{k[:-2]}_ratio"] = out["two levels"][k] / out["one level"][k]
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"{out['triangles']:,} triangles, {out['rays']:,} rays, median of {args.repeats}:")
    for name in runs:
        r = out[name]
        print(f"  {name:>10s}: build {r['build_s']:.3f} s, move the baffle "
              f"{r['move_small_s']:.3f} s, move the reflector {r['move_large_s']:.3f} s, "
              f"cast {r['cast_s']:.3f} s")
    print(f"  two levels / one level: build {out['build_ratio']:.2f}, move the baffle "
          f"{out['move_small_ratio']:.2f}, move the reflector {out['move_large_ratio']:.2f}, "
          f"cast {out['cast_ratio']:.2f}; {out['hits_that_differ']} of {out['rays']:,} "
          f"hits differ")
    return 0


if __name__ == "__main__":
    sys.exit(main())
