"""Beam and field angles against their closed forms over many seeds: is the mean unbiased,
and is the stated error the spread?

Luminaires with closed-form distributions, built here as USD stages:

- ``disc``: the Lambertian disc (I ~ cos gamma): beam 120 deg, field 168.52 deg, every plane;
- ``strips``: two long Lambertian strips tilted +-40 deg about their long axis (C90): along
  it a cosine (beam 120, field 168.52); across it (C0) cos(g - 40) + cos(g + 40), beam 160
  deg, and no field angle in the lower hemisphere (10% is only reached above the horizon);
- ``cos5`` and ``cos30``: a disc shaped to cos^5 and cos^30 (``shaping:focus``): beams
  2 acos(0.5^(1/n)), fields 2 acos(0.1^(1/n)).

Each is traced with ``--photons`` (and, with ``--target``, stopped by a files' target as the
command stops) for ``--seeds`` seeds; per figure the table gives the truth, the mean over the
seeds with its standard error, the mean minus the truth in those errors, and the seeds'
spread over the mean stated error (should be 0.7-1.3).

    python tools/beam_angle_seeds.py [--seeds 20] [--photons 1000000] [--target 0.02]
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "service"))

FIGURES = ("beam_angle_c0_c180", "beam_angle_c90_c270", "field_angle_c0_c180",
           "field_angle_c90_c270")


def _cos_n(n: float) -> dict:
    beam, field = (2 * math.degrees(math.acos(f ** (1.0 / n))) for f in (0.5, 0.1))
    return {"beam_angle_c0_c180": beam, "beam_angle_c90_c270": beam,
            "field_angle_c0_c180": field, "field_angle_c90_c270": field}


#: The closed forms (deg; None: undefined in the lower hemisphere).
TRUTH = {
    "disc": _cos_n(1.0),
    "strips": {"beam_angle_c0_c180": 160.0, "beam_angle_c90_c270": 120.0,
               "field_angle_c0_c180": None,
               "field_angle_c90_c270": 2 * math.degrees(math.acos(0.1))},
    "cos5": _cos_n(5.0),
    "cos30": _cos_n(30.0),
}


def build(name: str, folder: Path) -> Path:
    """The stage of luminaire ``name`` (metres, Z up, 1000 lm)."""
    import lumitrace  # noqa: F401  (registers the schema)
    from pxr import Gf, Usd, UsdGeom, UsdLux

    path = folder / f"{name}.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, "Z")
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(root.GetPrim())

    def flux(light, lm):
        light.GetPrim().ApplyAPI("LumitraceEmitterAPI")
        light.GetPrim().GetAttribute("lumitrace:luminousFlux").Set(lm)

    if name == "strips":
        for i, tilt in enumerate((40.0, -40.0)):
            light = UsdLux.RectLight.Define(stage, f"/Luminaire/Strip{i}")
            light.CreateWidthAttr(0.02)
            light.CreateHeightAttr(1.0)  # along Y: the long axis
            xf = UsdGeom.Xformable(light)
            xf.AddTranslateOp().Set(Gf.Vec3d(0.05 if tilt > 0 else -0.05, 0.0, 0.0))
            xf.AddRotateYOp().Set(tilt)
            flux(light, 500.0)
    else:
        light = UsdLux.DiskLight.Define(stage, "/Luminaire/Disc")
        light.CreateRadiusAttr(0.05)
        flux(light, 1000.0)
        if name.startswith("cos") and name != "cos1":
            n = float(name[3:])
            shaping = UsdLux.ShapingAPI.Apply(light.GetPrim())
            shaping.CreateShapingFocusAttr(n - 1.0)
    stage.Save()
    return path


def traced(stage: Path, seed: int, photons: int, target: float | None) -> dict:
    """The figures of one run."""
    from lumitrace.photometry.distribution import photometry_of
    from lumitrace.run.session import TraceSettings, run
    from lumitrace.stage.reader import read_stage

    scene = read_stage(stage)
    settings = TraceSettings(photons=photons, seed=seed, resolution=16, threads=2) \
        if target is None else TraceSettings(photons=None, target_error=target, seed=seed,
                                             resolution=16, threads=2)
    r = run(scene, settings)
    return photometry_of(scene, r.accumulator).figures.as_dict() | {"photons": r.photons}


def table(name: str, runs: list[dict]) -> list[str]:
    lines = []
    for key in FIGURES:
        truth = TRUTH[name][key]
        values = [r[key] for r in runs]
        if truth is None:
            shown = sum(v is not None for v in values)
            notes = {(r.get("spread_notes") or {}).get(key, "") for r in runs}
            lines.append(f"| {name} | {key} | - | defined in {shown} of {len(runs)} | | | "
                         f"{'; '.join(n for n in notes if n)} |")
            continue
        got = np.array([v for v in values if v is not None], np.float64)
        errs = np.array([r[key + "_error"] for r in runs if r[key] is not None], np.float64)
        if len(got) < 2:
            lines.append(f"| {name} | {key} | {truth:.2f} | undefined in "
                         f"{len(runs) - len(got)} | | | |")
            continue
        se = got.std(ddof=1) / math.sqrt(len(got))
        lines.append(f"| {name} | {key} | {truth:.2f} | {got.mean():.2f} +- {se:.2f} | "
                     f"{(got.mean() - truth) / se:+.2f} | "
                     f"{got.std(ddof=1) / errs.mean():.2f} | |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--target", type=float, default=None,
                    help="stop each run at this files' target instead of --photons")
    ap.add_argument("--only", nargs="*", default=sorted(TRUTH), choices=sorted(TRUTH))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        out = ["| luminaire | figure | truth (deg) | mean over seeds +- its error | "
               "(mean - truth) / error | spread / stated error | note |",
               "| --- | --- | --- | --- | --- | --- | --- |"]
        for name in args.only:
            stage = build(name, Path(tmp))
            runs = [traced(stage, seed, args.photons, args.target)
                    for seed in range(args.seeds)]
            out += table(name, runs)
            print(f"{name}: {np.mean([r['photons'] for r in runs]):,.0f} photons a run",
                  file=sys.stderr)
        print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
