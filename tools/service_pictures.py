"""A designer's edit as it reaches the pictures: a real ``lumitrace serve`` (its solids drawn
by the renderer it forks; ``--renderer process``: by one in a new interpreter; ``inline``:
in its own process) on a copy of the stage, converged to 2% first; then ``--edits`` material
edits (the reflector's specular reflectance), each sent once the last one's revision is
traced, written and drawn. Timed on the client, from the send to the status saying the
revision's pictures are written (polar curve and photometric solid in place).

    python tools/service_pictures.py [--stage stages/downlight.usda] [--edits 8]
                                     [--renderer fork|process|inline] [--json]

Run it against another checkout (``PYTHONPATH=OTHER/service``) in turn with this one to
compare the two.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from service_process import Service  # noqa: E402

REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"


def measure(stage: Path, edits: int) -> list[float]:
    """Seconds from each edit's send to its pictures written."""
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / stage.name
        shutil.copy(stage, copy)
        service = Service(copy, "--out", Path(tmp) / "out", "--no-sublayer", "--quiet",
                          "--target-error", "0.02")
        try:
            service.wait_status(lambda s: s.get("state") == "done"
                                and s.get("written_pictures"), timeout=300)
            times = []
            for k in range(edits):
                delta = {"op": "set", "path": REFLECTOR,
                         "property": "lumitrace:specularReflectance", "value": 0.80 + 0.01 * k}
                t0 = time.perf_counter()
                revision = service.client.send([delta])["revision"]
                service.wait_done(revision, pictures=True, timeout=300)
                times.append(time.perf_counter() - t0)
            return times
        finally:
            service.stop()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--stage", type=Path, default=HERE.parent / "stages" / "downlight.usda")
    p.add_argument("--edits", type=int, default=8)
    p.add_argument("--renderer", choices=("fork", "process", "inline"), default="fork",
                   help="the solids drawn by the renderer the service forks (the default), "
                        "by one in a new interpreter, or in the service's own process")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    os.environ["LUMITRACE_RENDERER"] = args.renderer
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    times = measure(args.stage, args.edits)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    out = {"stage": str(args.stage), "edits": args.edits, "renderer": args.renderer,
           "median_s": statistics.median(times), "max_s": max(times), "service_cpu_s": cpu}
    if args.json:
        print(json.dumps(out))
    else:
        where = {"fork": "by the renderer it forks", "process": "by a new interpreter",
                 "inline": "in the service"}[args.renderer]
        print(f"{args.stage.name}, {args.edits} material edits, solids drawn {where}: from "
              f"the send to the pictures written, median {out['median_s']:.2f} s, slowest "
              f"{out['max_s']:.2f} s; the service's CPU (its renderer's included) {cpu:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
