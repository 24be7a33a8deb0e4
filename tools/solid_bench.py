"""The photometric solid's drawing, one solid after another as a service draws them: in a
window of its own each time (``draw_solid``, a process without a renderer) against the
renderer's kept window (submitted and waited for, PNG in place), interleaved, in one run.

    python tools/solid_bench.py [--solids 8] [--json]

The solid is the size a run writes (73 x 73 directions around a 512-triangle luminaire);
each is a little different from the one before. The renderer is started first and has
drawn one solid, as a service's has by the time its first edit lands; this process has
drawn one too (VTK loaded: each solid timed here pays its window, not the import).
Medians and the ratio kept / own window, pair by pair.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "service"))

from lumitrace.photometry import solid_render  # noqa: E402


def solid(k: int):
    """A cosine-power lobe on 73 x 73 directions around 512 triangles, ``k`` its power."""
    c = np.radians(np.linspace(0.0, 360.0, 73))[:, None]
    g = np.radians(np.linspace(0.0, 180.0, 73))[None, :]
    cd = 300.0 * np.maximum(np.cos(g), 0.0) ** (1 + k % 3) * (1.0 + 0.1 * k) + 0.0 * c
    r = cd / cd.max()
    pts = np.stack([r * np.sin(g) * np.cos(c), r * np.sin(g) * np.sin(c), -r * np.cos(g)], -1)
    tri = np.random.default_rng(k).random((512, 3, 3)) * 0.05
    return pts, cd, tri


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--solids", type=int, default=8)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    os.environ["LUMITRACE_RENDERER"] = "process"
    renderer = solid_render.start_renderer()
    if renderer is None:
        print("no renderer here (pyvista missing, or one core)", file=sys.stderr)
        return 1
    own, kept = [], []
    with tempfile.TemporaryDirectory() as tmp:
        # the renderer loaded and warmed up, as a service's is when its first edit lands
        first = renderer.submit(Path(tmp) / "first.png", *solid(0), "Z", "first")
        if first is None or not renderer.wait(first):
            print("the renderer failed its first solid", file=sys.stderr)
            return 1
        time.sleep(1.0)
        # and VTK loaded here too: each solid below pays its window, not the import
        solid_render.draw_solid(Path(tmp) / "first_here.png", *solid(0), "Z", "first")
        for k in range(1, args.solids + 1):
            t = time.perf_counter()
            solid_render.draw_solid(Path(tmp) / f"own{k}.png", *solid(k), "Z", f"solid {k}")
            own.append(time.perf_counter() - t)
            t = time.perf_counter()
            job = renderer.submit(Path(tmp) / f"kept{k}.png", *solid(k), "Z", f"solid {k}")
            if job is None or not renderer.wait(job):
                print("the renderer failed a solid", file=sys.stderr)
                return 1
            kept.append(time.perf_counter() - t)
            same = (Path(tmp) / f"own{k}.png").read_bytes() == \
                (Path(tmp) / f"kept{k}.png").read_bytes()
            if not same:
                print(f"solid {k}: the two pictures differ", file=sys.stderr)
                return 1
    solid_render.stop_renderer()
    out = {"solids": args.solids, "own_window_s": statistics.median(own),
           "kept_window_s": statistics.median(kept),
           "kept_over_own": statistics.median(b / a for a, b in zip(own, kept))}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"{args.solids} solids, 73 x 73 directions, 512 triangles, medians:")
        print(f"  in a window of its own (this process): {out['own_window_s']:.3f} s")
        print(f"  by the renderer, its window kept:      {out['kept_window_s']:.3f} s "
              f"(submit to PNG in place)")
        print(f"  kept / own, pair by pair: {out['kept_over_own']:.2f}; "
              "every pair the same PNG to the byte")
    return 0


if __name__ == "__main__":
    sys.exit(main())
