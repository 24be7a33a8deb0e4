"""The accuracy page's tables and plots: the photometric files against the reference
stages' closed forms, and the stated error against the true error over many seeds.

    python tools/accuracy_page.py [--photons 1000000] [--seeds 20] [--target-error 0.02]
                                  [--page docs/explanation/accuracy.md] [--images docs/img]
                                  [--dry-run]

Each reference stage with a closed form is traced (``--photons``, seed 1) and its files'
grid compared with the closed form: the flux, the peak and the beam angle against theirs
(with the stated standard errors and the z-scores), and the grid's true relative RMS error
over the sphere against the one it states. Then each of three stages is traced with
``--seeds`` seeds until its files reach ``--target-error``, as ``lumitrace trace`` stops:
the true error's RMS over the stated one (1 where the statement is honest) and the mean
squared z-score of the grid's values (1 where every sigma is honest). The tables replace
the page's text between its two ``accuracy-page`` markers; the plots go to ``--images``.
``--dry-run`` prints the tables and leaves the page as it is.
"""
from __future__ import annotations

import argparse
import datetime
import math
import platform
import sys
import warnings
from pathlib import Path

import numpy as np

from side_by_side import grid_true_error

from lumitrace.photometry.accuracy import grid_accuracy
from lumitrace.photometry.distribution import C_STEP, photometry_of
from lumitrace.report.references import expected_figures, read_expectation
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "stages" / "reference"
PAGE = ROOT / "docs" / "explanation" / "accuracy.md"
IMAGES = ROOT / "docs" / "img"
START, END = "<!-- accuracy-page:start -->", "<!-- accuracy-page:end -->"
#: Stages whose whole distribution has a closed form (the grid is compared value by value).
DISTRIBUTIONS = ("isotropic", "lambertian_disc", "fresnel_slab", "mirror_cup")
#: Stages with closed-form figures only (their flux).
FIGURES_ONLY = ("integrating_sphere", "paraboloid")
#: Stages of the seed study.
SEEDED = ("isotropic", "lambertian_disc", "mirror_cup")


def machine() -> str:
    """The machine the figures were measured on, in words."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import os

    return f"{cpu}, {os.cpu_count()} cores, {platform.system()}, Python {platform.python_version()}"


def _z(value, truth, error) -> str:
    if value is None or error is None or not error > 0:
        return "-"
    return f"{(value - truth) / error:+.1f}"


def _closed_form_peak(expectation: dict, up_axis: str) -> float:
    """The closed form's largest intensity (cd), on a 0.05 deg raster of gamma (the
    reference distributions are rotationally symmetric)."""
    from lumitrace.photometry import frame
    from lumitrace.report.references import expected_intensity

    g = np.linspace(0.0, 180.0, 3601)
    return float(expected_intensity(expectation, frame.directions(np.zeros_like(g), g,
                                                                  up_axis)).max())


def closed_forms(photons: int) -> tuple[list[list[str]], dict]:
    """One run per reference stage: rows of the table, and the profiles for the plot."""
    rows, profiles = [], {}
    for name in DISTRIBUTIONS + FIGURES_ONLY:
        stage = REFERENCE / f"{name}.usda"
        expectation = read_expectation(stage)
        figures = expected_figures(expectation)
        scene = read_stage(stage)
        acc = run(scene, TraceSettings(photons=photons, seed=1)).accumulator
        ph = photometry_of(scene, acc)
        f = ph.figures
        flux = f"{f.luminous_flux:.2f} +- {f.luminous_flux_error:.2f} " \
               f"({figures['escaped_flux']:.2f}, z {_z(f.luminous_flux, figures['escaped_flux'], f.luminous_flux_error)})"
        peak_truth = _closed_form_peak(expectation, scene.up_axis) \
            if name in DISTRIBUTIONS else None
        peak = "-" if peak_truth is None else \
            f"{f.peak_intensity:.2f} +- {f.peak_intensity_error:.2f} ({peak_truth:.2f}, " \
            f"z {_z(f.peak_intensity, peak_truth, f.peak_intensity_error)})"
        stated = grid_accuracy(ph.grid, C_STEP).rms
        if name in DISTRIBUTIONS:
            true, z = grid_true_error(expectation, scene.up_axis, ph.grid)
            grid = f"{stated:.2%} / {true:.2%}; {float(np.nanmean(z ** 2)):.2f}"
            profiles[name] = (ph.grid, expectation, scene.up_axis)
        else:
            grid = f"{stated:.2%} / -; -"
        rows.append([f"`{name}`", f"{acc.photons:,}", flux, peak, grid])
    return rows, profiles


def seeded(seeds: int, target: float) -> tuple[list[list[str]], dict]:
    """The seed study: rows of the table, and each seed's (stated, true) for the plot."""
    rows, points = [], {}
    for name in SEEDED:
        stage = REFERENCE / f"{name}.usda"
        scene, expectation = read_stage(stage), read_expectation(stage)
        stats = []
        for seed in range(1, seeds + 1):
            acc = run(scene, TraceSettings(target_error=target, seed=seed)).accumulator
            grid = photometry_of(scene, acc).grid
            true, z = grid_true_error(expectation, scene.up_axis, grid)
            stats.append((acc.photons, grid_accuracy(grid, C_STEP).rms, true,
                          float(np.nanmean(z ** 2))))
        a = np.array(stats)
        points[name] = a[:, 1:3]
        ratio = math.sqrt(float((a[:, 2] ** 2).mean()) / float((a[:, 1] ** 2).mean()))
        rows.append([f"`{name}`", f"{np.median(a[:, 0]):,.0f}", f"{a[:, 1].mean():.2%}",
                     f"{ratio:.3f}", f"{int((a[:, 2] > a[:, 1]).sum())} of {seeds}",
                     f"{a[:, 3].mean():.2f}"])
    return rows, points


def _table(head: list[str], rows: list[list[str]]) -> str:
    return "\n".join(["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
                     + ["| " + " | ".join(r) + " |" for r in rows]) + "\n"


def plot_profiles(profiles: dict, path: Path) -> None:
    """The C0-C180 profile of each file against its closed form, with the band of one
    standard error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lumitrace.report.references import expected_intensity
    from lumitrace.photometry import frame

    fig, axes = plt.subplots(1, len(profiles), figsize=(3.2 * len(profiles), 3.0),
                             constrained_layout=True)
    for ax, (name, (grid, expectation, up)) in zip(np.atleast_1d(axes), profiles.items()):
        full = grid.full()
        c0 = int(np.argmin(np.abs(full.c - 0.0)))
        g = full.gamma
        fine = np.linspace(0.0, 180.0, 721)
        truth = expected_intensity(expectation, frame.directions(np.zeros_like(fine), fine,
                                                                 up))
        ax.plot(fine, truth, color="0.2", lw=1.0, label="closed form")
        ax.fill_between(g, full.candela[c0] - full.sigma[c0], full.candela[c0]
                        + full.sigma[c0], color="tab:orange", alpha=0.35, lw=0)
        ax.plot(g, full.candela[c0], ".", color="tab:orange", ms=3, label="file, C0")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("gamma (deg)", fontsize=8)
        ax.set_xlim(0, 180)
        ax.tick_params(labelsize=7)
    np.atleast_1d(axes)[0].set_ylabel("intensity (cd)", fontsize=8)
    np.atleast_1d(axes)[0].legend(fontsize=7)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_seeds(points: dict, path: Path) -> None:
    """Each seed's true error against the error its files state."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.0, 3.6), constrained_layout=True)
    top = 0.0
    for name, a in points.items():
        ax.plot(a[:, 0] * 100, a[:, 1] * 100, "o", ms=3.5, label=name)
        top = max(top, float(a.max()) * 100)
    ax.plot([0, top * 1.05], [0, top * 1.05], color="0.3", lw=0.8, label="true = stated")
    ax.set_xlabel("stated relative RMS error (%)", fontsize=8)
    ax.set_ylabel("true relative RMS error (%)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def page_text(photons: int, seeds: int, target: float, forms: list, seeds_rows: list) -> str:
    when = datetime.date.today().isoformat()
    return (f"Measured by `python tools/accuracy_page.py --photons {photons} --seeds {seeds} "
            f"--target-error {target}` on {when} ({machine()}).\n\n"
            "**The files against the closed forms**, one run of each reference stage "
            f"({photons:,} photons, seed 1). Each figure is the file's value +- its stated "
            "standard error (the closed form's value, and the z-score of the difference); "
            "the grid column is the relative RMS error the files state over the sphere, "
            "their true one against the closed form's cell means, and the mean squared "
            "z-score of every grid value (1 where every stated sigma is honest).\n\n"
            + _table(["stage", "photons", "flux (lm)", "peak (cd)",
                      "grid: stated / true error; mean z^2"], forms)
            + "\n![The files' C0-C180 profiles against the closed forms]"
              "(../img/accuracy-profiles.png)\n\n"
            f"**The stated error over {seeds} seeds**, each run stopped by "
            f"`--target-error {target}` as the command stops: the true error's RMS over the "
            "stated error's RMS (1 where the statement is honest), how often a run's true "
            "error was above its stated one (about half the time, for a standard error), "
            "and the mean squared z-score of the grid's values.\n\n"
            + _table(["stage", "photons (median)", "stated error (mean)",
                      "true / stated (RMS)", "true above stated", "mean z^2"], seeds_rows)
            + "\n![Each seed's true error against its stated error](../img/accuracy-seeds.png)\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--target-error", type=float, default=0.02)
    ap.add_argument("--page", type=Path, default=PAGE)
    ap.add_argument("--images", type=Path, default=IMAGES)
    ap.add_argument("--dry-run", action="store_true", help="print the tables, leave the page")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    forms, profiles = closed_forms(args.photons)
    seeds_rows, points = seeded(args.seeds, args.target_error)
    text = page_text(args.photons, args.seeds, args.target_error, forms, seeds_rows)
    print(text)
    args.images.mkdir(parents=True, exist_ok=True)
    plot_profiles(profiles, args.images / "accuracy-profiles.png")
    plot_seeds(points, args.images / "accuracy-seeds.png")
    if args.dry_run:
        return 0
    page = args.page.read_text()
    head, _, rest = page.partition(START)
    _, _, tail = rest.partition(END)
    args.page.write_text(f"{head}{START}\n{text}{END}{tail}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
