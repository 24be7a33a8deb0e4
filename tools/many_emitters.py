"""Many small emitters against one: photons per second of a board of N x N disk LEDs (each
1/N^2 of the flux) and of the same board with one LED of the whole flux, traced in turn
with the same photons, geometry (a white diffuse board behind the LEDs and a mirror cup
around them), resolution and threads, in one run; the ratio is N^2 LEDs over one.

    python tools/many_emitters.py [--side 100] [--photons 2000000] [--repeats 3]
                                  [--threads 2] [--resolution 64] [--per-light] [--json]

The board's lights are grouped as the stage reader groups them (:mod:`lumitrace.scene.groups`);
``--per-light`` traces them one by one instead, as before grouping. Each trace is a whole
:func:`lumitrace.run.session.run` (rounds, tallies, the map's estimate) followed by the
photometric files' grid (:func:`~lumitrace.photometry.distribution.photometry_of`), timed
on the wall clock and in process CPU seconds; medians of ``--repeats``.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time

import numpy as np


from lumitrace.photometry.distribution import photometry_of
from lumitrace.run.session import TraceSettings, run
from lumitrace.scene import Emitter, Material, Scene
from lumitrace.scene.groups import group_emitters

#: Board side (m), LED disk radius (m), cup height (m).
BOARD, RADIUS, CUP = 0.2, 0.0008, 0.1


def _quad(a, b, c, d) -> list:
    return [[a, b, c], [a, c, d]]


def board_scene(side: int, per_light: bool = False) -> Scene:
    """``side`` x ``side`` LEDs (one if ``side`` is 1) facing down from a white board,
    inside an open mirror box: the same triangles and materials for any ``side``; the LEDs
    grouped as the stage reader groups them unless ``per_light``."""
    h = BOARD / 2
    z0, z1 = 0.0, -CUP
    tri = _quad([-h, -h, 0.001], [-h, h, 0.001], [h, h, 0.001], [h, -h, 0.001])  # faces down
    walls = []
    for (x0, y0), (x1, y1) in (((-h, -h), (h, -h)), ((h, -h), (h, h)), ((h, h), (-h, h)),
                               ((-h, h), (-h, -h))):
        walls += _quad([x0, y0, z0], [x1, y1, z0], [x1, y1, z1], [x0, y0, z1])
    triangles = np.array(tri + walls, dtype=np.float64)
    material = np.array([0, 0] + [1] * len(walls), np.int32)
    materials = (Material("/Board", "diffuse", reflectance=0.8),
                 Material("/Cup", "mirror", reflectance=0.9))
    centres = (np.arange(side) + 0.5) / side * BOARD - h
    emitters = []
    for i, x in enumerate(centres):
        for j, y in enumerate(centres):
            m = np.eye(4)
            m[:3, 3] = (x, y, 0.0)
            emitters.append(Emitter(path=f"/Board/Led_{i}_{j}", kind="disk",
                                    flux=1.0 / side**2, to_world=m, radius=RADIUS))
    return Scene(triangles, material, np.zeros(len(triangles), np.int32), materials,
                 ("/Board",), tuple(emitters) if per_light else group_emitters(emitters))


def one(scene: Scene, settings: TraceSettings) -> dict:
    """One whole trace and its files' grid: wall and CPU seconds, photons per second of
    each, and the seconds the grid took."""
    w, c = time.perf_counter(), time.process_time()
    r = run(scene, settings)
    traced = time.perf_counter()
    photometry_of(r.scene, r.accumulator)
    wall, cpu = time.perf_counter() - w, time.process_time() - c
    return {"wall_s": wall, "cpu_s": cpu, "photons": r.photons, "files_s": wall - (traced - w),
            "photons_per_s": r.photons / wall, "photons_per_cpu_s": r.photons / cpu}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--side", type=int, default=100, help="LEDs along each side of the board")
    ap.add_argument("--photons", type=int, default=2_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--per-light", action="store_true",
                    help="trace the lights one by one (not grouped)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    settings = TraceSettings(photons=args.photons, resolution=args.resolution, seed=1,
                             threads=args.threads, workers="threads")
    scenes = {"many": board_scene(args.side, args.per_light), "one": board_scene(1)}
    one(scenes["one"], TraceSettings(photons=1000, resolution=8, threads=1,
                                     workers="threads"))  # kernels loaded
    rows: dict[str, list] = {k: [] for k in scenes}
    for _ in range(args.repeats):  # interleaved: a drifting machine moves both alike
        for name, scene in scenes.items():
            rows[name].append(one(scene, settings))
    summary = {name: {k: statistics.median(r[k] for r in runs) for k in runs[0]}
               for name, runs in rows.items()}
    summary["leds"] = args.side ** 2
    summary["ratio_photons_per_s"] = (summary["many"]["photons_per_s"]
                                      / summary["one"]["photons_per_s"])
    summary["ratio_photons_per_cpu_s"] = (summary["many"]["photons_per_cpu_s"]
                                          / summary["one"]["photons_per_cpu_s"])
    if args.json:
        print(json.dumps(summary, indent=1))
        return 0
    print(f"{args.photons:,} photons, resolution {args.resolution}, {args.threads} threads, "
          f"median of {args.repeats}:")
    for name, label in (("one", "1 LED"), ("many", f"{args.side ** 2:,} LEDs")):
        s = summary[name]
        print(f"  {label:>11s}: {s['wall_s']:.2f} s wall ({s['files_s']:.2f} s the files' "
              f"grid), {s['cpu_s']:.2f} CPU s, {s['photons_per_s']:,.0f} photons/s, "
              f"{s['photons_per_cpu_s']:,.0f} per CPU s")
    print(f"  {args.side ** 2:,} LEDs / 1 LED: {summary['ratio_photons_per_s']:.2f} of the "
          f"photons per second, {summary['ratio_photons_per_cpu_s']:.2f} per CPU second")
    return 0


if __name__ == "__main__":
    sys.exit(main())
