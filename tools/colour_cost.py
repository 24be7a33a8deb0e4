"""What colour costs: spectral against monochrome tracing of the same luminaire, in one run.

Traces ``stages/warm_downlight.usda`` (a 3000 K LED and a champagne reflector: photons carry
a spectral throughput) and the same scene with its surfaces made neutral (the same scalar
albedos: nothing spectral is traced, the light's colour comes from its spectrum alone),
interleaved, and reports CPU seconds per million photons of each (median of the repeats),
their ratio, and how far the two maps' luminous flux differ. It also states what
single-wavelength sampling (each photon one wavelength drawn by luminous power) would add:
the relative variance per photon of X and Z that the spectral throughput does not have.

    python tools/colour_cost.py [--photons 2000000] [--repeats 3] [--json]
"""
from __future__ import annotations

import argparse
import dataclasses
import warnings
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "service"))

from lumitrace.run.session import TraceSettings, run  # noqa: E402
from lumitrace.scene import spectra  # noqa: E402
from lumitrace.stage.reader import read_stage  # noqa: E402


def neutral(scene):
    """The scene with every surface's spectra removed (scalar albedos kept)."""
    mats = tuple(dataclasses.replace(m, reflectance_spectrum=(), specular_spectrum=(),
                                     transmittance_spectrum=(), abbe_number=0.0)
                 for m in scene.materials)
    return dataclasses.replace(scene, materials=mats)


def single_wavelength_variance(spd) -> dict:
    """Relative variance per escaping photon of X and Z (and Y = 0) if each photon carried
    one wavelength drawn in proportion to power times ybar: the spectral noise that the
    throughput photons do not have."""
    cmf = spectra.observer()
    p = np.asarray(spd) * cmf[:, 1]
    p = p / p.sum()
    out = {}
    for k, name in ((0, "X"), (2, "Z")):
        r = cmf[:, k] / cmf[:, 1]
        m, m2 = p @ r, p @ (r * r)
        out[name] = float((m2 - m * m) / (m * m))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=float, default=2e6)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")  # the short warm-up run's notes
    spectral = read_stage(ROOT / "stages" / "warm_downlight.usda")
    plain = neutral(spectral)
    assert spectral.colour == "spectral" and plain.colour == "emitters"
    settings = TraceSettings(photons=int(args.photons), resolution=32, seed=1, threads=2)
    run(spectral, TraceSettings(photons=10_000, resolution=8))  # kernels loaded
    cpu = {"spectral": [], "monochrome": []}
    flux = {}
    for _ in range(args.repeats):
        for name, scene in (("monochrome", plain), ("spectral", spectral)):
            t0 = time.process_time()
            r = run(scene, settings)
            cpu[name].append(time.process_time() - t0)
            flux[name] = r.accumulator.fluxes()["escaped"]
    per_m = {k: statistics.median(v) / (args.photons / 1e6) for k, v in cpu.items()}
    report = {
        "photons": int(args.photons), "repeats": args.repeats,
        "cpu_s_per_million_photons": per_m,
        "spectral_over_monochrome": per_m["spectral"] / per_m["monochrome"],
        "escaped_lm": flux,
        "single_wavelength_relative_variance_per_photon": single_wavelength_variance(
            spectral.emitters[0].spectrum),
    }
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        print(f"{report['photons']:,} photons, median of {args.repeats}, CPU s per million:")
        for k, v in per_m.items():
            print(f"  {k:10s} {v:6.2f}")
        print(f"  spectral / monochrome = {report['spectral_over_monochrome']:.2f}")
        print(f"  escaped flux: spectral {flux['spectral']:.1f} lm, surfaces neutral "
              f"{flux['monochrome']:.1f} lm (their scalar albedo is the D65 luminous mean "
              "of the spectrum; the 3000 K LED weights the red, where the reflector "
              "reflects more)")
        v = report["single_wavelength_relative_variance_per_photon"]
        print(f"  single-wavelength photons would add a relative variance per photon of "
              f"{v['X']:.2f} (X) and {v['Z']:.2f} (Z), none to Y")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
