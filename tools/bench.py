#!/usr/bin/env python3
"""Tracer throughput on the demo stage against bare embreex on the same rays, one run.

    python tools/bench.py [--seconds S] [--threads K] [--stage STAGE]

Prints tracer path segments per second, bare ``EmbreeScene.run`` rays per second on the
very same rays (same threads, same process, right after) and their ratio, then the JSON.
"""
from __future__ import annotations

import argparse
import json

from lumitrace.run.bench import run_benchmark


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--stage", default=None)
    p.add_argument("--workers", choices=("processes", "threads"), default="processes")
    a = p.parse_args()
    r = run_benchmark(stage=a.stage, seconds=a.seconds, threads=a.threads, workers=a.workers)
    print(f"{r['stage']}: {r['triangles']} triangles, {r['threads']} {r['workers']}, "
          f"{r['photons']:,} photons, {r['segments']:,} segments")
    print(f"tracer   {r['segments_per_second']:>14,.0f} segments/s")
    print(f"embreex  {r['raw_rays_per_second']:>14,.0f} rays/s (same rays)")
    print(f"ratio    {r['ratio']:>14.3f}")
    print(json.dumps(r))


if __name__ == "__main__":
    main()
