"""The design task of ``docs/fit.md``: a 6-point profile reflector around a small LED,
fitted to a 30 deg cos^n beam.

    python tools/fit_design.py [--make | --check] [--evaluations 800] [--photons 8192]
                               [--out DIR] [--docs DIR]

``--make`` writes the stage and the target into ``stages/`` (``--check``: exit 1 where the
committed files differ from what it would write):

- ``stages/profile_reflector.usda`` (millimetres): a Lambertian LED disc of 1.5 mm radius
  emitting down, 1000 lm, inside a revolved mirror profile of six points
  (``LumitraceProfileAPI``, specular reflectance 0.9, 64 segments), a cone from r = 2 mm
  at the LED's plane to r = 30 mm 50 mm below it; its mesh made from its profile;
- ``stages/beam30_cos20.ies``: I = I0 cos^n(gamma), n = ln 0.5 / ln cos 15 deg = 19.99
  (a beam angle of 30 deg: half the peak at 15 deg from nadir), nothing above the
  horizon, 1000 lm, rotationally symmetric, every degree.

Then it runs the command of ``docs/fit.md`` (``lumitrace fit``, the radii of the six points
and their heights, 12 parameters) into ``--out`` and, with ``--docs``, copies the report's
pictures and the best's own polar curve and photometric solid there.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: no spinning BLAS threads

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
STAGE = ROOT / "stages" / "profile_reflector.usda"
TARGET = ROOT / "stages" / "beam30_cos20.ies"
POINTS = "/Luminaire/Reflector.lumitrace:profile:points"
#: The parameters: the first point's radius near the LED, the others +-10 mm around the
#: cone's, every height +-4 mm (the points keep their order down the axis).
VARY = [f"{POINTS}[0][0]=1.5:6", f"{POINTS}[1:6][0]=+-10", f"{POINTS}[*][1]=+-4"]
BEAM_DEG = 30.0


def stage_text() -> str:
    """The stage's text (deterministic)."""
    sys.path.insert(0, str(ROOT / "service"))
    import lumitrace  # noqa: F401  (the schema plugin)
    from pxr import Gf, Usd, UsdGeom, UsdLux, UsdShade, Vt

    from lumitrace.delta.profile import write_profile_mesh

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 0.001)
    stage.GetRootLayer().documentation = (
        "A design task: a Lambertian LED (1.5 mm radius, 1000 lm) emitting down inside a "
        "revolved six-point mirror profile (LumitraceProfileAPI), a cone to begin with; "
        "lumitrace fit shapes it to stages/beam30_cos20.ies (tools/fit_design.py).")
    lum = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(lum.GetPrim())
    mat = UsdShade.Material.Define(stage, "/Luminaire/Materials/Aluminium")
    mat.GetPrim().ApplyAPI("LumitraceMaterialAPI")
    mat.GetPrim().GetAttribute("lumitrace:scattering").Set("mirror")
    mat.GetPrim().GetAttribute("lumitrace:specularReflectance").Set(0.9)
    prim = UsdGeom.Mesh.Define(stage, "/Luminaire/Reflector").GetPrim()
    prim.ApplyAPI("LumitraceProfileAPI")
    points = [(2.0 + 28.0 * t, -50.0 * t) for t in np.linspace(0.0, 1.0, 6)]
    prim.GetAttribute("lumitrace:profile:points").Set(
        Vt.Vec2fArray([Gf.Vec2f(float(r), float(z)) for r, z in points]))
    prim.GetAttribute("lumitrace:profile:segments").Set(64)
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(mat)
    write_profile_mesh(prim)
    led = UsdLux.DiskLight.Define(stage, "/Luminaire/LED")
    led.CreateRadiusAttr(1.5)
    led.GetPrim().ApplyAPI("LumitraceEmitterAPI")
    led.GetPrim().GetAttribute("lumitrace:luminousFlux").Set(1000.0)
    return stage.GetRootLayer().ExportToString()


def target_text() -> str:
    """The cos^n target's LM-63 text (deterministic: a fixed issue date)."""
    sys.path.insert(0, str(ROOT / "service"))
    from lumitrace.photometry.grid import CGammaGrid
    from lumitrace.photometry.lm63 import format_ies

    n = math.log(0.5) / math.log(math.cos(math.radians(BEAM_DEG / 2)))
    gamma = np.arange(0.0, 180.0 + 1e-9, 1.0)
    cd = np.clip(np.cos(np.radians(gamma)), 0.0, None) ** n * 1000.0 * (n + 1) / (2 * math.pi)
    grid = CGammaGrid(np.array([0.0]), gamma, cd[None, :], "rotational")
    return format_ies(grid, 1000.0, 0.0, 0.0, 0.0,
                      {"TEST": f"cos^{n:.2f} target, beam angle {BEAM_DEG:g} deg",
                       "ISSUEDATE": "2026-01-01", "MANUFAC": "lumitrace example",
                       "TESTLAB": "computed", "LUMINAIRE": "design target"})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    files = ap.add_mutually_exclusive_group()
    files.add_argument("--make", action="store_true", help="write the stage and the target")
    files.add_argument("--check", action="store_true",
                       help="exit 1 where the committed stage or target is out of date")
    ap.add_argument("--evaluations", type=int, default=800)
    ap.add_argument("--photons", type=int, default=8192)
    ap.add_argument("--out", type=Path, default=None, help="the fit's folder")
    ap.add_argument("--docs", type=Path, default=None,
                    help="copy the report's pictures into this folder")
    args = ap.parse_args(argv)
    wanted = {STAGE: stage_text(), TARGET: target_text()}
    if args.check:
        stale = [p.name for p, t in wanted.items()
                 if not p.exists() or p.read_bytes() != t.encode("utf-8")]
        if stale:
            print("out of date: " + ", ".join(stale), file=sys.stderr)
        return 1 if stale else 0
    if args.make:
        for path, text in wanted.items():
            path.write_bytes(text.encode("utf-8"))  # the IES file's CR LF lines kept
            print(f"wrote {path}")
    out = args.out or Path(tempfile.mkdtemp(prefix="fit-design-"))
    cmd = [sys.executable, "-m", "lumitrace.cli", "fit", str(STAGE), "--target", str(TARGET),
           "--vary", *VARY, "--evaluations", str(args.evaluations), "--photons",
           str(args.photons), "--out", str(out), "--json", "--no-progress"]
    if args.docs is None:
        cmd.append("--no-pictures")
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode:
        sys.stderr.write(run.stderr)
        return run.returncode
    summary = json.loads(run.stdout.splitlines()[-1])
    figures = json.loads((out / "fit.json").read_text())["best_figures"]
    print(f"{summary['evaluations']} evaluations, {summary['cpu_seconds']:.1f} CPU s, "
          f"{summary['seconds']:.1f} s: merit {summary['merit']:.4f} +- "
          f"{summary['merit_error']:.4f} (noise floor {summary['noise_floor']:.4f}); beam "
          f"{figures['beam_angle_c0_c180']:.2f} +- {figures['beam_angle_c0_c180_error']:.2f} "
          f"deg, light output ratio {figures['light_output_ratio']:.3f}")
    for name, value in summary["best"].items():
        print(f"  {name} = {value:.3f}")
    if args.docs is not None:
        args.docs.mkdir(parents=True, exist_ok=True)
        for name in ("fit.merit.png", "fit.polar.png", "fit.parameters.png",
                     "fit.profile.png"):
            shutil.copyfile(out / name, args.docs / name)
        for key, name in (("polar_diagram", "best.polar.png"),
                          ("photometric_solid", "best.solid.png")):
            if summary["files"].get(key):
                shutil.copyfile(summary["files"][key], args.docs / name)
        print(f"pictures in {args.docs}")
    if args.out is None:
        shutil.rmtree(out, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
