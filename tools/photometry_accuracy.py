"""How far the photometric files and the two maps are from the closed forms.

    python tools/photometry_accuracy.py [--photons 1000000 16000000] [--stages lambertian_disc mirror_cup]

Each reference stage (a copy) is traced and its outputs written; the IES file is read back
and compared, gamma band by gamma band (averaged over C and the band's gammas), with the
closed form's point values and with its cell means (what a cell measures). Printed too:
flux above the horizon, the z-scores of every file value against its stated standard error
(the sidecar JSON), the peak and beam angles with their errors, and the true relative RMS
error over the sphere of the filtered map ``Y`` and the raw map ``raw.Y``.
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from lumitrace.film.cubemap import texel_solid_angles
from lumitrace.film.texel_quadrature import texel_integrals
from lumitrace.photometry import frame
from lumitrace.photometry.lm63 import read_ies
from lumitrace.publish.outputs import write_outputs
from lumitrace.report.references import expected_intensity, read_expectation
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage

REFERENCE = Path(__file__).resolve().parents[1] / "stages" / "reference"

#: The gamma bands (deg) of the table, inclusive.
BANDS = [(30.0, 40.0), (50.0, 50.0), (60.0, 70.0), (77.5, 80.0), (87.5, 87.5), (90.0, 90.0)]


def _cell_means(expectation, gammas, samples=400):
    edges = np.radians(np.concatenate([[0.0], 0.5 * (gammas[1:] + gammas[:-1]), [180.0]]))
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        g = lo + (np.arange(samples) + 0.5) * (hi - lo) / samples
        w = np.sin(g)
        d = frame.directions(np.zeros_like(g), np.degrees(g), "Z")
        out.append(float((expected_intensity(expectation, d) * w).sum() / w.sum()))
    return np.array(out)


def _beam(expectation, samples=1_800_001):
    """The closed form's beam (50%) angle (deg), on a fine raster: the full angle between
    the crossings of half the peak in a vertical plane (rotational symmetry)."""
    g = np.linspace(0.0, 90.0, samples)
    d = frame.directions(np.zeros_like(g), g, "Z")
    prof = expected_intensity(expectation, d)
    return float(2.0 * g[np.flatnonzero(prof >= 0.5 * prof.max())[-1]])


def _map_error(image, expectation, res):
    omega = texel_solid_angles(res)
    truth = texel_integrals(lambda d: expected_intensity(expectation, d), res) / omega
    return math.sqrt(float((omega * (image - truth) ** 2).sum() / (omega * truth ** 2).sum()))


def measure(name: str, photons: int, seed: int) -> dict:
    src = REFERENCE / f"{name}.usda"
    expectation = read_expectation(src)
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / src.name
        shutil.copy(src, stage)
        scene = read_stage(stage)
        t0 = time.perf_counter()
        result = run(scene, TraceSettings(photons=photons, seed=seed))
        t_trace = time.perf_counter() - t0
        t0 = time.perf_counter()
        record = write_outputs(result, None, pictures=False)
        t_write = time.perf_counter() - t0
        ies = read_ies(record["ies"]).grid()
        data = json.loads(Path(record["photometry_data"]).read_text())
    sigma = np.array(data["sigma"])
    g = ies.gamma
    point = expected_intensity(expectation, frame.directions(np.zeros_like(g), g, "Z"))
    cells = _cell_means(expectation, g)
    mean_c = ies.candela.mean(axis=0)
    bands = []
    for lo, hi in BANDS:
        sel = (g >= lo) & (g <= hi)
        p, c, v = point[sel].sum(), cells[sel].sum(), mean_c[sel].sum()
        bands.append({"band": f"{lo:g}-{hi:g}" if lo != hi else f"{lo:g}",
                      "vs_point": v / p - 1.0 if p > 1e-9 * point.max() else None,
                      "cd": float(v / sel.sum()),
                      "point_cd": float(p / sel.sum()),
                      "vs_cell": v / c - 1.0 if c > 0 else None})
    live = sigma > 0
    z = ((ies.candela - cells[None, :]) / np.where(live, sigma, 1.0))[live]
    est = result.estimate
    beam_truth = _beam(expectation)
    return {"stage": name, "photons": photons, "trace_s": t_trace, "write_s": t_write,
            "beam_truth": beam_truth,
            "bands": bands, "upward_fraction": record["upward_flux_fraction"],
            "z_max": float(np.abs(z).max()), "z_var": float(np.var(z)), "z_n": int(z.size),
            "peak": record["peak_intensity"], "peak_error": record["peak_intensity_error"],
            "peak_truth": float(cells.max()),
            "beam": record["beam_angle_c0_c180"], "beam_error": record["beam_angle_c0_c180_error"],
            "file_error": record["photometry_error"],
            "map_error_Y": _map_error(est.filtered, expectation, result.settings.resolution),
            "map_error_raw": _map_error(est.raw, expectation, result.settings.resolution)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photons", type=int, nargs="+", default=[1_000_000, 16_000_000])
    ap.add_argument("--stages", nargs="+", default=["lambertian_disc", "mirror_cup"])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    rows = [measure(s, n, seed=7 + i) for i, (s, n) in
            enumerate((s, n) for s in args.stages for n in args.photons)]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    for r in rows:
        print(f"\n{r['stage']} at {r['photons']:,} photons (trace {r['trace_s']:.1f} s, "
              f"outputs {r['write_s']:.2f} s)")
        print("  gamma band        " + "".join(f"{b['band']:>11}" for b in r["bands"]))
        for key, label in (("vs_point", "IES / point - 1"), ("vs_cell", "IES / cell mean - 1")):
            print(f"  {label:18}" + "".join(
                f"{'n/a' if b[key] is None else f'{b[key]:+.2%}':>11}" for b in r["bands"]))
        print("  IES cd            " + "".join(f"{b['cd']:11.3f}" for b in r["bands"]))
        print(f"  upward flux fraction {r['upward_fraction']:.3%}; z of {r['z_n']} file values "
              f"against their sigma: max |z| {r['z_max']:.2f}, variance {r['z_var']:.2f}")
        pm = lambda v, e: "n/a" if v is None else \
            f"{v:.2f} +- {'n/a' if e is None else f'{e:.2f}'}"  # noqa: E731
        print(f"  peak {pm(r['peak'], r['peak_error'])} cd (largest cell mean "
              f"{r['peak_truth']:.2f}); beam {pm(r['beam'], r['beam_error'])} deg "
              f"(closed form {r['beam_truth']:.2f}); "
              f"files' relative RMS error {r['file_error']:.2%}")
        print(f"  true relative RMS error over the sphere: Y {r['map_error_Y']:.2%}, "
              f"raw.Y {r['map_error_raw']:.2%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
