"""Convergence report: error against time and photons, raw against filtered maps.

Runs a session and, after every iteration, records the elapsed time, the photons, the
estimated error of the raw map and of the filtered map at several thresholds and, where a
reference is known (the stage's closed form, or a long run's EXR), their true relative RMS
error, PSNR and SSIM. Writes ``report.json``, PNG plots and an ``index.html`` showing them.
"""
from __future__ import annotations

import html
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..atomic import atomic_path, write_text
from ..film.convergence import estimate, relative_rms
from ..film.cubemap import texel_directions, texel_solid_angles, sample_map
from ..errors import LumitraceError
from .metrics import psnr, ssim
from ..run.session import Progress, TraceSettings, run
from ..run.settings import DEFAULT_THRESHOLD

ERROR_LEVELS = (0.05, 0.02)


#: Filter thresholds a report compares by default: the raw map (0), two lighter filters
#: and the default one.
REPORT_THRESHOLDS = (0.0, 512.0, 2500.0, DEFAULT_THRESHOLD)


@dataclass
class Reference:
    """A map taken as the truth (cd, (6R, R)) and where it came from."""

    intensity: np.ndarray
    source: str


def analytic_reference(stage_path: str | os.PathLike, resolution: int) -> Reference | None:
    """The exact texel averages of the stage's closed form, when it has one."""
    from .references import expected_intensity, read_expectation
    from ..film.texel_quadrature import texel_integrals

    try:
        exp = read_expectation(stage_path)
    except (KeyError, FileNotFoundError):
        return None
    if exp.get("kind") not in ("isotropic", "lambertian", "fresnel_slab"):
        return None
    integ = texel_integrals(lambda d: expected_intensity(exp, d), resolution)
    return Reference(integ / texel_solid_angles(resolution),
                     f"closed form ({exp['kind']}): {exp.get('description', '')}")


def exr_reference(path: str | os.PathLike, resolution: int) -> Reference:
    """A long run's intensity EXR (its unfiltered ``raw.Y``), resampled if needed."""
    from ..publish.exr import read_intensity_exr

    channels, meta, _ = read_intensity_exr(path)
    image = channels.get("raw.Y", channels.get("Y"))
    if image is None:
        raise LumitraceError("has neither a raw.Y nor a Y channel", where=str(path))
    image = np.asarray(image, dtype=np.float64)
    if image.shape[1] != resolution:
        dirs = texel_directions(resolution).reshape(-1, 3)
        image = sample_map(image, dirs).reshape(6 * resolution, resolution)
    photons = meta.get("photons", "?")
    return Reference(image, f"{Path(path).name} ({photons} photons)")


@dataclass
class ReportSettings:
    """What the report traces: stop criteria, map resolution, the filter thresholds
    compared (0, the raw map, always among them: the baseline), seed and threads."""

    photons: int | None = None
    seconds: float | None = 30.0
    resolution: int = 64
    thresholds: tuple[float, ...] = REPORT_THRESHOLDS
    seed: int = 0
    threads: int = field(default_factory=lambda: os.cpu_count() or 1)

    def __post_init__(self) -> None:
        # the raw map (threshold 0) is the baseline every filtered curve is compared with
        object.__setattr__(self, "thresholds",
                           tuple(sorted({0.0, *map(float, self.thresholds)})))


def crossing_time(times, errors, level) -> float | None:
    """First time the error falls to ``level``, interpolated in log-log between iterations."""
    for i, (t, e) in enumerate(zip(times, errors)):
        if e <= level:
            if i == 0:
                return float(t)
            t0, e0 = times[i - 1], errors[i - 1]
            f = (math.log(e0) - math.log(level)) / (math.log(e0) - math.log(e))
            return float(math.exp(math.log(t0) + f * (math.log(t) - math.log(t0))))
    return None


def run_report(stage: str | os.PathLike, out_dir: str | os.PathLike,
               settings: ReportSettings = ReportSettings(),
               reference_exr: str | os.PathLike | None = None,
               progress: Callable[[Progress], None] | None = None) -> dict:
    """Trace ``stage``, record convergence after every iteration, write the report files."""
    from ..stage.reader import read_stage

    scene = read_stage(stage)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    res = settings.resolution
    ref = (exr_reference(reference_exr, res) if reference_exr is not None
           else analytic_reference(stage, res))
    omega = texel_solid_angles(res)
    main_t = max(settings.thresholds)
    rows: list[dict] = []
    snapshots: dict[int, dict] = {}

    overhead = [0.0]  # seconds spent here, not tracing: kept out of the time axis

    def record(p: Progress) -> None:
        t0 = time.perf_counter()
        row = {"iteration": p.iteration, "photons": p.photons,
               "seconds": p.seconds - overhead[0], "estimated": {}, "true": {}, "psnr": {},
               "ssim": {}, "peak_ratio": {}}
        for t in settings.thresholds:
            e = p.estimate if t == main_t else estimate(p.accumulator, t)
            key = f"{t:g}"
            row["estimated"][key] = e.error
            if ref is not None:
                img = e.filtered
                row["true"][key] = relative_rms(img, ref.intensity, omega)
                row["psnr"][key] = psnr(img, ref.intensity)
                row["ssim"][key] = ssim(img, ref.intensity)
                row["peak_ratio"][key] = float(img.max() / ref.intensity.max())
            if t in (0.0, main_t):
                snapshots.setdefault(p.iteration, {})[key] = e.filtered
        rows.append(row)
        overhead[0] += time.perf_counter() - t0
        if progress is not None:
            progress(p)

    trace = TraceSettings(photons=settings.photons, seconds=settings.seconds, resolution=res,
                          threshold=main_t, seed=settings.seed, threads=settings.threads)
    result = run(scene, trace, progress=record)

    times = [r["seconds"] for r in rows]
    crossings: dict[str, dict[str, float | None]] = {}
    if ref is not None:
        for t in settings.thresholds:
            key = f"{t:g}"
            errs = [r["true"][key] for r in rows]
            crossings[key] = {f"{lv:g}": crossing_time(times, errs, lv) for lv in ERROR_LEVELS}
    speedups = {}
    for key, c in crossings.items():
        if key == "0":
            continue
        speedups[key] = {lv: (crossings["0"][lv] / c[lv]) if c[lv] and crossings["0"].get(lv)
                         else None for lv in c}

    picked = _pick_snapshots(sorted(snapshots))
    paths = _plots(out, rows, settings.thresholds, ref, snapshots, picked, main_t)
    data = {
        "stage": str(stage), "luminaire": scene.luminaire_path,
        "reference": ref.source if ref is not None else None,
        "resolution": res, "seed": settings.seed, "threads": settings.threads,
        "thresholds": list(settings.thresholds),
        "error_definition": "relative RMS error over the sphere: "
                            "sqrt(sum(dOmega (I - I_ref)^2) / sum(dOmega I_ref^2))",
        "photons": result.photons, "seconds": result.seconds, "iterations": result.iterations,
        "figures": _figures(scene, result),
        "warnings": list(scene.warnings),
        "time_to_error": crossings,
        "speedup_filtered_over_raw": speedups,
        "iterations_data": rows,
        "images": {k: Path(v).name for k, v in paths.items()},
    }
    json_path = out / "report.json"
    write_text(json_path, json.dumps(data, indent=1))
    html_path = out / "index.html"
    write_text(html_path, _html(data))
    return {"json": str(json_path), "html": str(html_path), **{k: str(v) for k, v in paths.items()},
            "data": data}


def _figures(scene, result) -> dict:
    """The measured photometric figures of the final result, with their standard errors
    (JSON-safe: undefined figures are null)."""
    from ..photometry.distribution import photometry_of
    from ..publish.record import defined

    return {k: defined(list(v) if isinstance(v, tuple) else v)
            for k, v in photometry_of(scene, result.accumulator,
                                      result.settings.seed).figures.as_dict().items()}


def _pick_snapshots(iterations: list[int]) -> list[int]:
    """First, a middle and the last iteration."""
    if len(iterations) <= 3:
        return iterations
    return [iterations[0], iterations[len(iterations) // 3], iterations[-1]]


def _plots(out: Path, rows, thresholds, ref, snapshots, picked, main_t) -> dict[str, Path]:
    from ..pyplot import pyplot

    plt = pyplot()

    from ..publish.exr import cube_to_latlong

    paths = {}
    colours = plt.cm.viridis(np.linspace(0, 0.85, len(thresholds)))
    for x_key, x_label, name in (("seconds", "time (s)", "error_vs_time"),
                                 ("photons", "photons", "error_vs_photons")):
        fig, ax = plt.subplots(figsize=(7, 4.5), dpi=110)
        x = [r[x_key] for r in rows]
        for t, c in zip(thresholds, colours):
            key = f"{t:g}"
            label = "raw" if t == 0 else f"filtered, threshold {key}"
            if ref is not None:
                ax.loglog(x, [r["true"][key] for r in rows], "-o", ms=3, color=c,
                          label=f"{label} (true)")
            ax.loglog(x, [r["estimated"][key] for r in rows], "--", color=c,
                      label=f"{label} (estimated)")
        for lv in ERROR_LEVELS:
            ax.axhline(lv, color="grey", lw=0.6, ls=":")
        ax.set_xlabel(x_label)
        ax.set_ylabel("relative RMS error")
        ax.set_title("convergence" + (f" against {ref.source.split(':')[0]}" if ref else ""))
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
        ax.legend(fontsize=7)
        fig.tight_layout()
        paths[name] = out / f"{name}.png"
        with atomic_path(paths[name]) as tmp:
            fig.savefig(tmp, format="png")
        plt.close(fig)

    cols = ["0", f"{main_t:g}"] + (["reference"] if ref is not None else [])
    fig, axes = plt.subplots(len(picked), len(cols), figsize=(3.3 * len(cols), 1.9 * len(picked)),
                             dpi=110, squeeze=False)
    vmax = float(ref.intensity.max()) if ref is not None else max(
        float(snapshots[i][cols[1]].max()) for i in picked)
    # a log scale over four decades, so that a narrow beam and the dim rest both show
    from matplotlib.colors import LogNorm

    norm = LogNorm(vmin=max(vmax, 1e-300) * 1e-4, vmax=max(vmax, 1e-300), clip=True)
    shown = None
    for r, it in enumerate(picked):
        row = next(x for x in rows if x["iteration"] == it)
        for c, key in enumerate(cols):
            img = ref.intensity if key == "reference" else snapshots[it][key]
            ax = axes[r][c]
            shown = ax.imshow(np.maximum(cube_to_latlong(img, height=90), norm.vmin),
                              cmap="inferno", norm=norm, extent=(-180, 180, -90, 90))
            title = ("reference" if key == "reference" else
                     ("raw" if key == "0" else f"filtered (threshold {key})"))
            ax.set_title(f"{title}\n{row['photons']:,} photons", fontsize=7)
            ax.set_xticks([-180, -90, 0, 90, 180])
            ax.set_yticks([-90, 0, 90])
            ax.tick_params(labelsize=6)
            if r == len(picked) - 1:
                ax.set_xlabel("longitude (deg)", fontsize=6)
            if c == 0:
                ax.set_ylabel("latitude (deg)", fontsize=6)
    fig.tight_layout()
    if shown is not None:
        bar = fig.colorbar(shown, ax=axes, shrink=0.8, pad=0.02)
        bar.set_label("intensity (cd, log scale)", fontsize=7)
        bar.ax.tick_params(labelsize=6)
    paths["maps"] = out / "maps.png"
    with atomic_path(paths["maps"]) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return paths


def _html(data: dict) -> str:
    esc = html.escape
    rows = []
    for key, c in data["time_to_error"].items():
        sp = data["speedup_filtered_over_raw"].get(key, {})
        cells = "".join(
            f"<td>{c[lv]:.3g} s</td>" if c[lv] is not None else "<td>not reached</td>"
            for lv in c)
        spc = "".join(f"<td>{sp[lv]:.2f}x</td>" if sp.get(lv) else "<td>-</td>" for lv in c)
        rows.append(f"<tr><td>{'raw' if key == '0' else 'threshold ' + esc(key)}</td>"
                    f"{cells}{spc if key != '0' else '<td>-</td>' * len(c)}</tr>")
    levels = [f"{lv:g}" for lv in ERROR_LEVELS]
    head = "".join(f"<th>time to {float(lv):.0%}</th>" for lv in levels) + \
        "".join(f"<th>speed-up at {float(lv):.0%}</th>" for lv in levels)
    table = (f"<table><tr><th>map</th>{head}</tr>{''.join(rows)}</table>" if rows
             else "<p>No reference: only estimated errors are shown.</p>")
    imgs = "".join(f'<figure><img src="{esc(v)}" alt="{esc(k)}"><figcaption>{esc(k)}'
                   f"</figcaption></figure>" for k, v in data["images"].items())
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>lumitrace convergence: {esc(Path(data['stage']).name)}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:1100px}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:4px 8px;text-align:right}}img{{max-width:100%}}</style></head>
<body><h1>Convergence of {esc(data['luminaire'])} in {esc(Path(data['stage']).name)}</h1>
<p>{data['photons']:,} photons in {data['iterations']} iterations, {data['seconds']:.1f} s,
resolution {data['resolution']}, seed {data['seed']}, {data['threads']} threads.
Reference: {esc(data['reference'] or 'none')}.<br>Error: {esc(data['error_definition'])}.</p>
{table}
{imgs}
<p>Data: <a href="report.json">report.json</a></p>
</body></html>
"""
