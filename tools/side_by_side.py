"""Speed on four small luminaires, in the figures a photon tracer is compared by.

    python tools/side_by_side.py [--photons 10000000] [--repeats 3] [--max-photons 64000000]
                                 [--scenes isotropic lambertian mirror_cup diffuse_cup]
                                 [--peer auto|none|PATH] [--throughput-only] [--json]

The four scenes are built as stages (in a temporary folder): an isotropic point source and
a Lambertian disc in free space, and a Lambertian point source at the rim of an open
cylinder (radius 25 mm, 50 mm long) that is a 95% specular mirror or 85% white paint.

Per scene:

- throughput: ``lumitrace trace`` run as a user runs it (the ``lumitrace`` command in a
  subprocess, ``--photons``, no pictures), its process CPU seconds (median of
  ``--repeats``) and photons per CPU second, and the same of the peer, run interleaved
  with it (one of each, in turn). Each of our runs is made twice: with the stage read by
  USD (its kept scene dropped first, as after an edit) and with the scene the first
  kept (the same stage run again: no USD loaded, see ``lumitrace.stage.scene_cache``);
- the user's view: the real ``lumitrace trace --target-error E`` at E = 2% and 1% (judged
  on the files, the default), whole process, CPU and wall seconds (read by USD, then
  kept, as above), against the peer's CPU
  seconds to E on its grid (medians of ``--repeats`` runs), and against the peer's whole
  process to E (its photons to E, run beside ours in each repeat: the median of the
  repeats' ratios); and the files' true error at the stop against the closed form;
  beside it the USD floor (Python, numpy and USD loaded, the stage opened: what any USD
  tool pays) in the same run, over the same peer's CPU seconds: the least ratio any
  tool that reads the stage with USD can show;
- convergence: a run in this process that records, after every iteration, the relative RMS
  error ``sqrt(sum(Omega (I - I_ref)^2) / sum(Omega I_ref^2))`` over the cells of a
  C 15 deg x gamma 5 deg grid, of the raw estimate (the goniophotometer's counts: what
  the IES and LDT files hold) and of the filtered cube map (averaged over each cell), and
  the photons and seconds (time spent measuring left out) at which each first reaches 2%
  and 1%. For the map, ``I_ref`` is averaged over the same texels (the texels' size is
  not the map's error). ``I_ref`` is the closed form's cell mean (isotropic, Lambertian, mirror cup:
  I = (Phi / pi) cos(gamma) rho^k(gamma)); the diffuse cup has none, so its reference is a
  run of 4x ``--max-photons`` photons with another seed, whose own variance (from its
  stated standard errors) is taken out of the squared error.

The peer is eulumdat-goniosim, a Rust Monte Carlo photon tracer for luminaires (analytic
cylinder, its own binning), tracing the same four scenes (``tools/peer``, built with cargo
on first use). Its time to a level is our raw files' photons to that level over its photons
per CPU second: both are analog estimators, equal in error at equal photons. Without cargo
(``--peer none``) the ratios use ``PEER_CPU_SECONDS``, measured on another day on a machine
of this kind that ran the peer 1.4-1.8x faster than a later one did: a stale reference.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: no spinning BLAS threads

import argparse
import json
import math
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import make_stages as ms  # noqa: E402  (the reference stages' builders)

from lumitrace.film.cubemap import texel_directions, texel_solid_angles  # noqa: E402
from lumitrace.film.texel_quadrature import texel_integrals  # noqa: E402
from lumitrace.photometry import frame  # noqa: E402
from lumitrace.photometry.measured import cell_fluxes, cell_solid_angle_grid  # noqa: E402
from lumitrace.report.convergence_report import crossing_time  # noqa: E402
from lumitrace.report.references import expected_intensity, read_expectation  # noqa: E402
from lumitrace.run.session import TraceSettings, run  # noqa: E402
from lumitrace.stage.reader import read_stage  # noqa: E402

#: The ``lumitrace`` command as a user starts it: the installed entry point (its launcher
#: catches signals from the first instant and starts the picture renderer early), else the
#: same launcher through this interpreter.
_SCRIPT = Path(sys.executable).with_name("lumitrace")
LUMITRACE = [str(_SCRIPT)] if _SCRIPT.is_file() else [
    sys.executable, "-c", "import sys, lumitrace_launch; sys.exit(lumitrace_launch.main())"]

#: Process CPU seconds of the peer tracer at 10M photons (median of 3), stored from an
#: earlier run: the reference when the peer cannot be built.
PEER_CPU_SECONDS = {"isotropic": 0.96, "lambertian": 1.2, "mirror_cup": 2.6,
                    "diffuse_cup": 3.2}
C_STEP, GAMMA_STEP = 15.0, 5.0
GAMMAS = np.arange(0.0, 180.0 + 1e-9, GAMMA_STEP)
LEVELS = (0.02, 0.01)


def diffuse_cup():
    """The mirror cup's geometry in 85% white paint (no closed form)."""
    stage = ms.mirror_cup()
    wall = stage.GetPrimAtPath("/Luminaire/Wall")
    paint = ms.make_material(stage, "Paint", "diffuse", reflectance=0.85)
    ms.bind(wall, paint)
    layer = stage.GetRootLayer()
    data = dict(layer.customLayerData)
    data.pop(ms.EXPECTATION_KEY, None)  # no closed form
    layer.customLayerData = data
    return stage


def point_source():
    """The isotropic source as a point (UsdLux ``treatAsPoint``), as the peer's scene has
    it: the reference stage's 1 mm sphere also samples a point on its surface."""
    from pxr import UsdLux

    stage = ms.isotropic()
    UsdLux.SphereLight(stage.GetPrimAtPath("/Luminaire/Source")).CreateTreatAsPointAttr(True)
    return stage


BUILDERS = {"isotropic": point_source, "lambertian": ms.lambertian_disc,
            "mirror_cup": ms.mirror_cup, "diffuse_cup": diffuse_cup}


def build(name: str, folder: Path) -> Path:
    """The scene's stage, saved a minute ago (as a user's stage is saved before a run: a
    file written in the last seconds is not trusted to keep its read scene)."""
    path = folder / f"{name}.usda"
    stage = BUILDERS[name]()
    path.write_text(stage.GetRootLayer().ExportToString(), encoding="utf-8")
    when = time.time() - 60.0
    os.utime(path, (when, when))
    return path


def forget_scene(stage: Path) -> None:
    """Drop the scene kept for ``stage`` (:mod:`lumitrace.stage.scene_cache`): the next run
    reads the stage with USD, as the first run after an edit does."""
    from lumitrace.stage.scene_cache import entry_path

    entry = entry_path(stage)
    if entry is not None:
        entry.unlink(missing_ok=True)


PEER_DIR = HERE / "peer"


def peer_binary(choice: str) -> Path | None:
    """The peer's executable: ``choice`` a path, ``none``, or ``auto`` (built with cargo in
    ``tools/peer`` when missing; None without cargo)."""
    if choice == "none":
        return None
    if choice != "auto":
        return Path(choice)
    exe = PEER_DIR / "target" / "release" / "peer-bench"
    if not exe.exists():
        if shutil.which("cargo") is None:
            return None
        print("building the peer (tools/peer) with cargo ...", file=sys.stderr, flush=True)
        subprocess.run(["cargo", "build", "--release", "--quiet", "--manifest-path",
                        str(PEER_DIR / "Cargo.toml")], check=True)
    return exe


def _timed(cmd: list[str], **run) -> tuple[float, float, subprocess.CompletedProcess]:
    """Process CPU seconds (user + system) and wall seconds of one run of ``cmd``
    (``subprocess.run`` with ``run``), and the finished process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, **run)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, wall, p


def _cpu_of(cmd: list[str]) -> tuple[float, float]:
    """Process CPU seconds and wall seconds of one run of ``cmd``, which must succeed."""
    return _timed(cmd, check=True, stdout=subprocess.DEVNULL)[:2]


def throughput(stage: Path, name: str, photons: int, repeats: int, out: Path,
               peer: Path | None) -> dict:
    """Process CPU seconds of ``lumitrace trace`` (median of ``repeats``), as run by a user,
    and of the peer on the same scene, interleaved; or the stored peer figure."""
    ours = [*LUMITRACE, "trace", str(stage), "--photons",
            str(photons), "--no-pictures", "--quiet", "--no-sublayer", "--out", str(out),
            "--replace-results"]
    runs, cold, peer_cpu = [], [], []
    for _ in range(repeats):
        if peer is not None:
            peer_cpu.append(_cpu_of([str(peer), name, str(photons)])[0])
        forget_scene(stage)
        cold.append(_cpu_of(ours))  # the stage read with USD (it keeps its scene)
        runs.append(_cpu_of(ours))  # the kept scene: an unchanged stage run again
    c = float(np.median([r[0] for r in runs]))
    c_cold = float(np.median([r[0] for r in cold]))
    if peer_cpu:
        p, source = float(np.median(peer_cpu)), "measured in this run"
    else:
        p, source = PEER_CPU_SECONDS[name] * photons / 10_000_000, "stored"
    return {"cpu_seconds": c, "wall_seconds": float(np.median([r[1] for r in runs])),
            "photons_per_cpu_second": photons / c, "peer_cpu_seconds": p,
            "peer_photons_per_cpu_second": photons / p, "ratio_to_peer": p / c,
            "cold_cpu_seconds": c_cold, "cold_ratio_to_peer": p / c_cold,
            "peer": source}


def time_to_levels(t: dict) -> dict:
    """CPU seconds to each level: ours with the filtered map and with the raw files at our
    photons per CPU second, the peer's (raw) at its own, and ours (filtered) over the
    peer's."""
    out = {}
    for lv in LEVELS:
        raw, filt = (t[f"{k}_{lv:g}"]["photons"] for k in ("raw", "filtered"))
        row = {"ours_filtered": filt and filt / t["photons_per_cpu_second"],
               "ours_raw": raw and raw / t["photons_per_cpu_second"],
               "peer": raw and raw / t["peer_photons_per_cpu_second"]}
        row["filtered_over_peer"] = (row["ours_filtered"] / row["peer"]
                                     if filt and raw else None)
        out[f"{lv:g}"] = row
    return out


def _raw_grid(acc) -> tuple[np.ndarray, np.ndarray]:
    """The goniophotometer's cell means (cd) and their variances on the grid."""
    omega = cell_solid_angle_grid(GAMMAS, C_STEP)
    flux = cell_fluxes(acc, GAMMAS, C_STEP)
    w = acc.emitters[0].photon_flux  # Poisson: analog photons of one weight
    return flux / omega, w * flux / omega**2


class _MapCells:
    """Solid-angle weighted means of a cube map over the grid's cells."""

    def __init__(self, resolution: int, up_axis: str):
        d = texel_directions(resolution).reshape(-1, 3)
        c, g = frame.angles(d, up_axis)
        plane = np.round(np.mod(c, 360.0) / C_STEP).astype(int) % int(360 / C_STEP)
        mids = 0.5 * (GAMMAS[1:] + GAMMAS[:-1])
        zone = np.searchsorted(mids, g)
        self.cell = plane * len(GAMMAS) + zone
        self.omega = texel_solid_angles(resolution).ravel()
        self.n = int(360 / C_STEP) * len(GAMMAS)
        self.weight = np.bincount(self.cell, self.omega, self.n)

    def __call__(self, image: np.ndarray) -> np.ndarray:
        s = np.bincount(self.cell, self.omega * image.ravel(), self.n)
        return (s / np.maximum(self.weight, 1e-300)).reshape(-1, len(GAMMAS))

    def variance(self, flux: np.ndarray, photon_flux: float) -> np.ndarray:
        """Variance of the cell means of a raw map of texel fluxes ``flux`` (lm) from
        analog photons of ``photon_flux`` (lm) each (Poisson counts)."""
        s = np.bincount(self.cell, photon_flux * flux.ravel(), self.n)
        w = np.maximum(self.weight, 1e-300)  # a cell no texel centre falls in: 0, not 0 / 0
        return (s / w / w).reshape(-1, len(GAMMAS))


def closed_form_cells(expectation: dict, up_axis: str, sub: int = 24) -> np.ndarray:
    """The closed form's mean over every cell of the peer's grid (C 15 deg by gamma 5 deg,
    every cell a C sector, the poles' too: the raw grid counts them so)."""
    edges = np.concatenate([[0.0], 0.5 * (GAMMAS[1:] + GAMMAS[:-1]), [180.0]])
    return cell_means(expectation, up_axis, np.arange(0.0, 360.0, C_STEP), C_STEP,
                      edges[:-1], edges[1:], pooled_poles=False, sub=sub)


def cell_means(expectation: dict, up_axis: str, planes: np.ndarray, step: float,
               lo: np.ndarray, hi: np.ndarray, pooled_poles: bool, sub: int) -> np.ndarray:
    """The closed form's mean over cells (sin-weighted midpoint quadrature): C sectors of
    ``step`` deg around ``planes`` by gamma zones ``lo`` .. ``hi`` (deg); with
    ``pooled_poles`` the first and last zones are whole polar caps (all C)."""
    f = (np.arange(sub) + 0.5) / sub
    out = np.zeros((len(planes), len(lo)))
    for j, (g0, g1) in enumerate(zip(lo, hi)):
        g = g0 + f * (g1 - g0)
        pole = pooled_poles and j in (0, len(lo) - 1)
        for i, c0 in enumerate(planes):
            cs = np.arange(0.0, 360.0, 360.0 / sub) if pole else c0 - 0.5 * step + f * step
            cc, gg = np.meshgrid(cs, g, indexing="ij")
            w = np.sin(np.radians(gg))
            d = frame.directions(cc, gg, up_axis).reshape(-1, 3)
            v = expected_intensity(expectation, d).reshape(cc.shape)
            out[i, j] = float((v * w).sum() / w.sum())
    return out


def rms(value: np.ndarray, ref: np.ndarray, ref_var: np.ndarray | None = None) -> float:
    omega = cell_solid_angle_grid(GAMMAS, C_STEP)
    num = float((omega * (value - ref) ** 2).sum())
    if ref_var is not None:
        num = max(num - float((omega * ref_var).sum()), 0.0)
    return math.sqrt(num / float((omega * ref**2).sum()))


class _Done(Exception):
    pass


def convergence(stage: Path, max_photons: int, resolution: int, seed: int = 1) -> dict:
    """Errors of the raw grid and the filtered map after every iteration, and where they
    first reach each level. The map is compared with the reference averaged over the same
    texels, so the comparison measures the map's noise and filter bias, not its texels'
    size."""
    scene = read_stage(stage)
    try:
        expectation = read_expectation(stage)
    except KeyError:
        expectation = None
    cells = _MapCells(resolution, scene.up_axis)
    if expectation is not None:
        ref = closed_form_cells(expectation, scene.up_axis)
        truth = texel_integrals(lambda d: expected_intensity(expectation, d), resolution)
        ref_map = cells(truth / texel_solid_angles(resolution))
        ref_var = ref_map_var = None
        source = "closed form"
    else:
        n_ref = 4 * max_photons
        r = run(scene, TraceSettings(photons=n_ref, resolution=resolution, seed=seed + 1000))
        ref, ref_var = _raw_grid(r.accumulator)
        flux = r.accumulator.texel_flux()
        w = r.accumulator.emitters[0].photon_flux
        ref_map = cells(flux / texel_solid_angles(resolution))
        ref_map_var = cells.variance(flux, w)
        source = f"{n_ref:,} photons, seed {seed + 1000}"
    rows, overhead = [], [0.0]

    def record(p) -> None:
        t0 = time.perf_counter()
        raw, _ = _raw_grid(p.accumulator)
        rows.append({"photons": p.photons, "seconds": p.seconds - overhead[0],
                     "raw": rms(raw, ref, ref_var),
                     "filtered": rms(cells(p.estimate.filtered), ref_map, ref_map_var)})
        overhead[0] += time.perf_counter() - t0
        if rows[-1]["raw"] <= min(LEVELS) and rows[-1]["filtered"] <= min(LEVELS):
            raise _Done

    try:
        run(scene, TraceSettings(photons=max_photons, resolution=resolution, seed=seed),
            progress=record)
    except _Done:
        pass
    out = {"reference": source, "iterations": rows}
    for key in ("raw", "filtered"):
        for lv in LEVELS:
            errors = [r[key] for r in rows]
            out[f"{key}_{lv:g}"] = {
                axis: crossing_time([r[axis] for r in rows], errors, lv)
                for axis in ("photons", "seconds")}
    return out


def files_points(expectation: dict, up_axis: str, c: np.ndarray, gamma: np.ndarray,
                 sub: int = 12) -> np.ndarray:
    """The closed form as a published grid states it: at each listed gamma (a point),
    over each plane's C cell (planes ``c`` every C step all round); the poles one value."""
    step = float(c[1] - c[0]) if len(c) > 1 else 360.0
    f = (np.arange(sub) + 0.5) / sub
    out = np.zeros((len(c), len(gamma)))
    for i, c0 in enumerate(c):
        cc, gg = np.meshgrid(c0 - 0.5 * step + f * step, gamma, indexing="ij")
        d = frame.directions(cc, gg, up_axis).reshape(-1, 3)
        out[i] = expected_intensity(expectation, d).reshape(cc.shape).mean(axis=0)
    return out


def files_true_error(stage: Path, photometry_json: Path) -> float | None:
    """The written files' true relative RMS error over the sphere against the closed form
    (None for a stage without one), from the sidecar JSON's grid."""
    from lumitrace.photometry.grid import CGammaGrid

    try:
        expectation = read_expectation(stage)
    except KeyError:
        return None
    doc = json.loads(photometry_json.read_text())
    grid = CGammaGrid(np.array(doc["c"]), np.array(doc["gamma"]), np.array(doc["candela"]),
                      doc["symmetry"], np.array(doc["sigma"]), tuple(doc["poleCaps_deg"]))
    return grid_true_error(expectation, read_stage(stage).up_axis, grid)[0]


def grid_true_error(expectation: dict, up_axis: str, grid) -> tuple[float, np.ndarray]:
    """A published grid's true relative RMS error over the sphere against the closed
    form as the grid states it (:func:`files_points`), and each value's error over its
    standard error (NaN where it states none)."""
    full = grid.full()
    ref = files_points(expectation, up_axis, full.c, full.gamma)
    omega = cell_solid_angle_grid(full.gamma, float(full.c[1] - full.c[0]))
    true = math.sqrt(float((omega * (full.candela - ref) ** 2).sum())
                     / float((omega * ref ** 2).sum()))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(full.sigma > 0, (full.candela - ref) / full.sigma, np.nan)
    return true, z


#: The least any USD tool pays to read a stage: Python with numpy and USD's schemas
#: loaded and the stage opened (``python -c``, the stage's path after it).
USD_FLOOR = ("import sys, numpy; from pxr import Usd, UsdGeom, UsdLux, UsdShade; "
             "Usd.Stage.Open(sys.argv[1])")


def user_view(stage: Path, out: Path, t: dict, repeats: int = 3,
              peer: Path | None = None, name: str | None = None) -> dict:
    """The real ``lumitrace trace --target-error E`` (files judged, the default), whole
    process, at each level: CPU and wall seconds (medians of ``repeats``, each a run read
    by USD then one of the kept scene: a run of a few tenths of a second varies by a
    tenth), photons, the files' stated and true error at the stop; against the peer's
    CPU seconds to E on its grid, and the USD floor's (:data:`USD_FLOOR`, run just
    before each) against it: below the floor no USD tool goes. With the ``peer``'s
    executable, the peer's whole process to E (the photons its grid needs) runs beside
    ours in each repeat, and each repeat's ratio is taken: the machine's drift between
    repeats then moves both alike."""
    rows = {}
    for lv in LEVELS:
        cmd = [*LUMITRACE, "trace", str(stage), "--target-error",
               str(lv), "--no-pictures", "--json", "--no-progress", "--no-sublayer",
               "--out", str(out), "--replace-results"]
        to_e = t[f"raw_{lv:g}"]["photons"]
        runs, paired = [], []
        for _ in range(repeats):
            floor = _cpu_of([sys.executable, "-c", USD_FLOOR, str(stage)])[0]
            forget_scene(stage)
            cold = _run_summary(cmd)[:2]  # read with USD, as after an edit
            runs.append((floor, *cold, *_run_summary(cmd)))  # then the kept scene
            if peer is not None and to_e:
                paired.append(_cpu_of([str(peer), name, str(round(to_e))])[0])
        floor, cold_cpu, cold_wall, cpu, wall = (float(np.median([r[k] for r in runs]))
                                                 for k in range(5))
        summary = runs[-1][5]  # the same seed: every run traces the same photons
        ph = summary["photometry"]
        peer_cpu = t["cpu_seconds_to"][f"{lv:g}"]["peer"]
        rows[f"{lv:g}"] = {
            "cpu_seconds": cpu, "wall_seconds": wall, "photons": summary["photons"],
            "files_error": ph["photometry_error"], "files_worst": ph["photometry_worst_error"],
            "files_true_error": files_true_error(stage, Path(summary["outputs"]
                                                             ["photometry_data"])),
            "map_error_bound": summary["relative_error_bound"],
            "peer_cpu_seconds": peer_cpu,
            "cpu_over_peer": cpu / peer_cpu if peer_cpu else None,
            "usd_floor_cpu_seconds": floor,
            "usd_floor_over_peer": floor / peer_cpu if peer_cpu else None,
            "cold_cpu_seconds": cold_cpu, "cold_wall_seconds": cold_wall,
            "cold_cpu_over_peer": cold_cpu / peer_cpu if peer_cpu else None,
            "peer_process_photons": to_e if paired else None,
            "peer_process_cpu_seconds": float(np.median(paired)) if paired else None,
            "cpu_over_peer_process": float(np.median([r[3] / p for r, p in
                                                      zip(runs, paired)]))
            if paired else None}
    return rows


def _run_summary(cmd: list[str]) -> tuple[float, float, dict]:
    """CPU and wall seconds of one ``trace --json`` and its summary."""
    cpu, wall, p = _timed(cmd, capture_output=True, text=True)
    if p.returncode not in (0, 3):
        raise RuntimeError(f"{' '.join(cmd)} failed: {p.stderr[-2000:]}")
    return cpu, wall, json.loads(p.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photons", type=int, default=10_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--max-photons", type=int, default=64_000_000)
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--scenes", nargs="+", default=list(BUILDERS), choices=list(BUILDERS))
    ap.add_argument("--peer", default="auto",
                    help="the peer's executable, 'auto' (build tools/peer with cargo) or 'none'")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-user-view", action="store_true",
                    help="leave out the real trace --target-error commands")
    ap.add_argument("--throughput-only", action="store_true",
                    help="photons per CPU second against the peer alone (no convergence "
                         "runs, no user view)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from lumitrace.trace.aot import warm_up

    warm_up()  # kernels loaded once, before any convergence run is timed
    peer = peer_binary(args.peer)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name in args.scenes:
            stage = build(name, folder)
            t = throughput(stage, name, args.photons, args.repeats, folder / f"out_{name}",
                           peer)
            if args.throughput_only:
                rows[name] = t
                if not args.json:
                    _print_throughput(name, t)
                continue
            t.update(convergence(stage, args.max_photons, args.resolution))
            t["cpu_seconds_to"] = time_to_levels(t)
            if not args.no_user_view:
                t["user_view"] = user_view(stage, folder / f"user_{name}", t,
                                           args.repeats, peer, name)
            rows[name] = t
            if not args.json:
                _print(name, t)
    if args.json:
        print(json.dumps(rows, indent=1))
    return 0


def _fmt(x, unit):
    if x is None:
        return "not reached"
    return f"{x / 1e6:.2f}M" if unit == "photons" else f"{x:.2f} s"


def _print_throughput(name: str, t: dict, end: str = "\n") -> None:
    print(f"\n{name}: {t['photons_per_cpu_second'] / 1e6:.2f}M photons per CPU s "
          f"({t['cpu_seconds']:.2f} CPU s, {t['wall_seconds']:.2f} s wall); peer "
          f"{t['peer_photons_per_cpu_second'] / 1e6:.2f}M ({t['peer']}), ratio "
          f"{t['ratio_to_peer']:.2f} (stage read with USD: {t['cold_cpu_seconds']:.2f} CPU s, "
          f"ratio {t['cold_ratio_to_peer']:.2f})", end=end, flush=True)


def _print(name: str, t: dict) -> None:
    _print_throughput(name, t, end="")
    print(f"; reference: {t['reference']}")
    for key in ("raw", "filtered"):
        cells = [f"{lv:.0%}: {_fmt(t[f'{key}_{lv:g}']['photons'], 'photons')} photons, "
                 f"{_fmt(t[f'{key}_{lv:g}']['seconds'], 'seconds')}" for lv in LEVELS]
        print(f"  {key:8s} " + "; ".join(cells))
    for lv, row in t["cpu_seconds_to"].items():
        if row["filtered_over_peer"] is not None:
            print(f"  CPU s to {float(lv):.0%}: ours (filtered map) {row['ours_filtered']:.2f}, "
                  f"peer {row['peer']:.2f}: {row['filtered_over_peer']:.2f} of the peer's")
    for lv, u in t.get("user_view", {}).items():
        true = "no closed form" if u["files_true_error"] is None else \
            f"{u['files_true_error']:.2%}"
        ratio = "-" if u["cpu_over_peer"] is None else \
            f"{u['cpu_over_peer']:.2f} (read with USD {u['cold_cpu_seconds']:.2f} CPU s: " \
            f"{u['cold_cpu_over_peer']:.2f})"
        peer = "not reached" if u["peer_cpu_seconds"] is None else \
            f"{u['peer_cpu_seconds']:.2f} CPU s"
        print(f"  trace --target-error {float(lv):.0%}: {u['photons'] / 1e6:.2f}M photons, "
              f"{u['cpu_seconds']:.2f} CPU s ({u['wall_seconds']:.2f} s wall), files "
              f"{u['files_error']:.2%} (worst lit {u['files_worst']:.2%}), true {true}; "
              f"peer to {float(lv):.0%} on its grid {peer}: {ratio} of the peer's; the USD "
              f"floor {u['usd_floor_cpu_seconds']:.2f} CPU s"
              + ("" if u["usd_floor_over_peer"] is None else
                 f", {u['usd_floor_over_peer']:.2f} of the peer's"))
        if u.get("cpu_over_peer_process") is not None:
            print(f"    the peer's whole process to {float(lv):.0%} "
                  f"({u['peer_process_photons'] / 1e6:.2f}M photons) beside ours: "
                  f"{u['peer_process_cpu_seconds']:.2f} CPU s; ours over it, the median of "
                  f"the repeats' ratios: {u['cpu_over_peer_process']:.2f}")
    sys.stdout.flush()


if __name__ == "__main__":
    sys.exit(main())
