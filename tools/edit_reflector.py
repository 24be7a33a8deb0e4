"""Edit the demo luminaire's reflector through a running ``lumitrace serve`` and print the
beam angle as the result refines: what a DCC plug-in does, with ``lumitrace.client`` only.

    lumitrace serve stages/downlight.usda --out demo-results &
    python tools/edit_reflector.py [--url http://127.0.0.1:8650] [--reflectance 0.7]
"""
from __future__ import annotations

import argparse
import sys

from lumitrace.client import Client

REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--url", default="http://127.0.0.1:8650")
    p.add_argument("--token", default=None)
    p.add_argument("--reflectance", type=float, default=0.7,
                   help="new specular reflectance of the reflector (0..1)")
    p.add_argument("--roughness", type=float, default=None, help="new GGX roughness (0..1)")
    args = p.parse_args(argv)
    client = Client(args.url, args.token)
    deltas = [{"op": "set", "path": REFLECTOR, "property": "lumitrace:specularReflectance",
               "value": args.reflectance}]
    if args.roughness is not None:
        deltas.append({"op": "set", "path": REFLECTOR, "property": "lumitrace:roughness",
                       "value": args.roughness})
    history = client.history()
    last = history[-1].id if history else 0
    answer = client.send(deltas)
    revision = answer["revision"]
    print(f"revision {revision}: {answer['effect']['kind']} edit of "
          f"{', '.join(answer['effect']['materials']) or 'nothing traced'}")
    for event in client.events(last_id=last, timeout=300):
        if event.data.get("revision") != revision:
            continue
        if event.kind == "written":
            r = client.results()
            if r["revision"] != revision:
                continue
            beam = r["photometry"]["beam_angle_c0_c180"]
            peak = r["photometry"]["peak_intensity"]
            err = r["relative_error"]
            print(f"  {r['photons']:>10,} photons  error "
                  f"{'-' if err is None else f'{err:6.2%}'}  beam angle "
                  f"{'-' if beam is None else f'{beam:5.1f} deg'}  peak "
                  f"{'-' if peak is None else f'{peak:8.1f} cd'}"
                  f"{'  (with pictures)' if event.data.get('pictures') else ''}")
            if event.data.get("pictures"):
                return 0
        elif event.kind == "error":
            print(f"  error: {event.data.get('message')}", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
