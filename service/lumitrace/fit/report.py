"""The fit's report: ``fit.json`` (everything: the summary, every evaluation, the
parameters, the target) and ``fit.html`` with its pictures: the merit with its error
against evaluations and seconds, the target and the best overlaid in polar curves, how far
each parameter moved within its range and whether it sits on an edge, and the figures of
the best with their standard errors beside the target's."""
from __future__ import annotations

import html
import json
import math
from pathlib import Path

import numpy as np

from ..atomic import write_text
from ..photometry.curves import PLANES, plane_curve
from ..photometry.distribution import photometry_of
from .search import FAILED_MERIT

MERIT_PNG = "fit.merit.png"
POLAR_PNG = "fit.polar.png"
PARAMETERS_PNG = "fit.parameters.png"
PROFILE_PNG = "fit.profile.png"


def _json_safe(v):
    if isinstance(v, dict):
        return {str(k): _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


def target_figures(grid) -> dict:
    """Beam (50%) and field (10%) angles of a file's grid in both planes (deg, the
    outermost crossings of its plane profiles, linear between its angles)."""
    out = {}
    peak = float(np.max(grid.candela)) if grid.candela.size else 0.0
    for c, _, _, _, key in PLANES:
        ang, r, _ = plane_curve(grid, c, 1.0)
        for what, level in (("beam", 0.5), ("field", 0.1)):
            above = np.flatnonzero(r >= level * peak) if peak > 0 else []
            if len(above) == 0:
                out[f"{what}_angle_{key}"] = None
                continue
            i, j = int(above[0]), int(above[-1])

            def cross(a, b):
                if a == b or r[a] == r[b]:
                    return float(ang[a])
                return float(np.interp(level * peak, [r[b], r[a]], [ang[b], ang[a]]))
            lo = cross(i, i - 1) if i > 0 else float(ang[0])
            hi = cross(j, j + 1) if j + 1 < len(r) else float(ang[-1])
            out[f"{what}_angle_{key}"] = hi - lo
    return out


def write_reports(folder: Path, summary: dict, result, params, objective, target, traced,
                  record, pictures: bool = True, profiles: dict | None = None) -> None:
    """Write ``fit.json`` and ``fit.html`` (and, with ``pictures``, their PNGs) into
    ``folder``; ``profiles``: per profiled mesh, its (start, best) profile points."""
    folder = Path(folder)
    # measured as the files are: the luminous opening from the confirming trace's seed
    ph = photometry_of(traced.scene, traced.accumulator, traced.settings.seed)
    figs = ph.figures.as_dict()
    tfig = target_figures(target.grid) if target is not None else {}
    data = {**summary,
            "target": target.as_dict() if target is not None else None,
            "objective": {"absolute": objective.absolute, "symmetry": objective.symmetry,
                          "terms": [t.text for t in objective.terms],
                          "constraints": [t.text for t in objective.constraints]},
            "photon_steps": [list(s) for s in result.photon_steps],
            "evaluations_list": [e.as_dict() for e in result.evaluations],
            "best_figures": {k: figs.get(k) for k in
                             ("luminous_flux", "luminous_flux_error", "light_output_ratio",
                              "light_output_ratio_error", "peak_intensity",
                              "peak_intensity_error", "beam_angle_c0_c180",
                              "beam_angle_c0_c180_error", "beam_angle_c90_c270",
                              "beam_angle_c90_c270_error", "field_angle_c0_c180",
                              "field_angle_c0_c180_error", "field_angle_c90_c270",
                              "field_angle_c90_c270_error", "downward_flux_fraction",
                              "downward_flux_fraction_error")},
            "target_figures": tfig}
    images = {}
    if pictures:
        images = draw(folder, result, params, summary, target, ph, objective.absolute,
                      profiles or {})
    data["pictures"] = images
    write_text(folder / "fit.json", json.dumps(_json_safe(data), indent=1))
    write_text(folder / "fit.html", _html(data, images))


def draw(folder: Path, result, params, summary, target, ph, absolute: bool,
         profiles: dict) -> dict:
    """The report's pictures; returns their file names by kind."""
    from ..pyplot import pyplot

    plt = pyplot()
    out = {}
    evs = [e for e in result.evaluations if e.merit < FAILED_MERIT]  # traced ones
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    photons = np.array([e.photons for e in evs])
    levels = sorted(set(photons.tolist()))
    cmap = plt.get_cmap("viridis")
    for ax, x_of, label in ((axes[0], lambda e: e.index + 1, "evaluation"),
                            (axes[1], lambda e: e.seconds, "seconds")):
        for k, n in enumerate(levels):
            sel = [e for e in evs if e.photons == n]
            ax.errorbar([x_of(e) for e in sel], [e.merit for e in sel],
                        yerr=[e.merit_error for e in sel], fmt="o", ms=3, lw=0.8,
                        color=cmap(k / max(1, len(levels) - 1)), label=f"{n:,} photons")
        gens = sorted({e.generation for e in evs})
        floor = [float(np.median([e.noise for e in evs if e.generation == g])) for g in gens]
        last = [max(x_of(e) for e in evs if e.generation == g) for g in gens]
        if any(f > 0 for f in floor):  # (no target: no floor)
            ax.step(last, floor, where="pre", lw=1, ls=":", color="#555555",
                    label="noise floor (a perfect candidate)")
        best = np.minimum.accumulate([e.merit for e in evs])
        ax.plot([x_of(e) for e in evs], best, "-", lw=1, color="black", label="lowest so far")
        ax.axhline(summary["merit"], color="#c0392b", lw=1, ls="--",
                   label=f"confirmed {summary['merit']:.3g} +- {summary['merit_error']:.1g}")
        ax.set_xlabel(label)
        ax.set_ylabel("merit")
        ax.set_yscale("log")
        ax.grid(True, lw=0.4, alpha=0.6, which="both")
    axes[0].legend(fontsize=7, frameon=True, framealpha=0.9, loc="upper right")
    axes[0].set_title("each candidate's merit +- 1 standard error", fontsize=9)
    axes[1].set_title("against the search's wall-clock time", fontsize=9)
    fig.savefig(folder / MERIT_PNG, dpi=110)
    plt.close(fig)
    out["merit"] = MERIT_PNG

    if target is not None:
        fig = plt.figure(figsize=(13, 4.6), constrained_layout=True)
        t_flux = target.grid.flux()
        b_flux = ph.figures.luminous_flux
        unit = "cd" if absolute else "cd/klm of the light leaving"
        curves = []
        for grid, flux, who in ((target.grid, t_flux, "target"), (ph.grid, b_flux, "best")):
            per = 1.0 if absolute else (1000.0 / flux if flux > 0 else 1.0)
            curves.append([(who,) + plane_curve(grid, c, per) for c, *_ in PLANES])
        cart = fig.add_subplot(1, 3, 3)
        for k, (c, style, colour, label, key) in enumerate(PLANES):
            ax = fig.add_subplot(1, 3, k + 1, projection="polar")
            ax.set_theta_zero_location("S")
            for who_curves in curves:
                who, ang, r, s = who_curves[k]
                theta = np.radians(ang)
                if who == "best":
                    ax.fill_between(theta, np.maximum(r - s, 0), r + s, color=colour,
                                    alpha=0.25, lw=0)
                    ax.plot(theta, r, "-", lw=1.6, color=colour, label="best")
                    cart.fill_between(ang, np.maximum(r - s, 0), r + s, color=colour,
                                      alpha=0.25, lw=0)
                    cart.plot(ang, r, style, lw=1.5, color=colour, label=f"best {label}")
                else:
                    ax.plot(theta, r, "-", lw=1.1, color="black", label="target")
                    cart.plot(ang, r, style, lw=1.0, color="black", label=f"target {label}")
            ax.set_thetagrids(np.arange(0, 360, 30), [f"{int(a if a <= 180 else 360 - a)}°"
                                                       for a in range(0, 360, 30)])
            ax.set_title(f"{label}: target and best, {unit}", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.legend(fontsize=7, frameon=False, loc="lower left")
        reach = _reach(curves)
        cart.set_xlim(-reach, reach)
        cart.set_ylim(bottom=0)
        cart.set_xlabel("angle from nadir (deg): C180 / C270 left, C0 / C90 right",
                        fontsize=8)
        cart.set_ylabel(unit, fontsize=8)
        cart.tick_params(labelsize=7)
        cart.grid(True, lw=0.4, alpha=0.6)
        cart.legend(fontsize=7, frameon=False)
        cart.set_title("both planes; band: the best's +-1 standard error", fontsize=8)
        fig.savefig(folder / POLAR_PNG, dpi=110)
        plt.close(fig)
        out["polar"] = POLAR_PNG

    continuous = [p for p in params if not p.discrete]
    if continuous:
        fig, ax = plt.subplots(figsize=(8, max(2.0, 0.75 * len(continuous) + 1.0)),
                               constrained_layout=True)
        for i, p in enumerate(continuous):
            info = summary["parameters"][p.name]
            y = len(continuous) - 1 - i
            ax.plot([0, 1], [y, y], "-", color="#cccccc", lw=6, solid_capstyle="butt")
            s, b = p.to_unit(p.start), p.to_unit(info["best"])
            ax.annotate("", xy=(b, y), xytext=(s, y),
                        arrowprops=dict(arrowstyle="->", color="#2c5aa0", lw=1.4))
            ax.plot([s], [y], "o", ms=5, color="#888888")
            ax.plot([b], [y], "o", ms=6, color="#c0392b" if info["at_edge"] else "#2c5aa0")
            ax.text(-0.01, y + 0.18, f"{p.lo:.4g}", ha="left", va="bottom", fontsize=6,
                    color="#777777")
            ax.text(1.01, y + 0.18, f"{p.hi:.4g}", ha="right", va="bottom", fontsize=6,
                    color="#777777")
            ax.text(b, y - 0.22, f"{info['best']:.4g}", ha="center", va="top", fontsize=6,
                    color="#2c5aa0")
        for i, p in enumerate(continuous):  # each name over its bar: names are long
            ax.text(0.5, len(continuous) - 1 - i + 0.28, p.name, ha="center", va="bottom",
                    fontsize=7, family="monospace")
        ax.set_yticks([])
        ax.set_ylim(-0.7, len(continuous) - 0.2)
        ax.set_xlim(-0.03, 1.03)
        ax.set_xlabel("position in the range (0: low, 1: high); grey: start, blue: best, "
                      "red: best on an edge", fontsize=8)
        ax.tick_params(axis="x", labelsize=7)
        fig.savefig(folder / PARAMETERS_PNG, dpi=110)
        plt.close(fig)
        out["parameters"] = PARAMETERS_PNG
    if profiles:
        fig, axes = plt.subplots(1, len(profiles), figsize=(4.5 * len(profiles), 4.5),
                                 constrained_layout=True, squeeze=False)
        for ax, (path, (start, best)) in zip(axes[0], sorted(profiles.items())):
            for pts, style, colour, label in ((start, "--", "#888888", "start"),
                                              (best, "-", "#2c5aa0", "best")):
                pts = np.asarray(pts, np.float64)
                for sign in (1.0, -1.0):
                    ax.plot(sign * pts[:, 0], pts[:, 1], style, marker="o", ms=3, lw=1.3,
                            color=colour, label=label if sign > 0 else None)
            ax.axvline(0.0, lw=0.6, ls="-.", color="#bbbbbb")
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_xlabel("r (the mesh's units), mirrored about the axis", fontsize=8)
            ax.set_ylabel("z", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(True, lw=0.4, alpha=0.6)
            ax.legend(fontsize=7, frameon=False)
            ax.set_title(f"{path}: its profile's section", fontsize=8)
        fig.savefig(folder / PROFILE_PNG, dpi=110)
        plt.close(fig)
        out["profile"] = PROFILE_PNG
    return out


def _reach(curves) -> float:
    """Half-width (deg) of the Cartesian diagram: where the curves fall below 2% of their
    top, with a margin, at least 20 deg."""
    top = max(float(np.max(r)) for cs in curves for _, _, r, _ in cs) or 1.0
    lit = [float(np.max(np.abs(ang[r > 0.02 * top]))) for cs in curves
           for _, ang, r, _ in cs if np.any(r > 0.02 * top)]
    return float(min(180.0, max(20.0, 1.15 * max(lit, default=90.0))))


_CSS = ("body{font-family:system-ui,sans-serif;max-width:72rem;margin:1.5rem auto;"
        "padding:0 1rem;color:#222}table{border-collapse:collapse;margin:0.5rem 0 1.2rem}"
        "td,th{border-bottom:1px solid #ddd;padding:0.25rem 0.6rem;text-align:left;"
        "font-size:0.9rem}figure{display:inline-block;margin:0.5rem}"
        "img{max-width:100%;border:1px solid #eee}code{font-size:0.85rem}")


def _fmt(v, digits: int = 4) -> str:
    if v is None:
        return "-"
    if isinstance(v, str):
        return html.escape(v)
    return f"{v:.{digits}g}"


def _html(data: dict, images: dict) -> str:
    e = html.escape
    rows = []
    for name, p in data["parameters"].items():
        rng = "choices " + ", ".join(map(str, p["choices"])) if "choices" in p else \
            f"{p['range'][0]:.6g} .. {p['range'][1]:.6g}"
        moved = "-" if p["moved"] is None else f"{p['moved']:+.1%} of the range"
        edge = f"<b>{e(p['at_edge'])} edge</b>" if p["at_edge"] else ""
        start = p["start"] + 0.0 if not isinstance(p["start"], str) else p["start"]
        rows.append(f"<tr><td><code>{e(name)}</code></td><td><code>{e(p['path'])}</code></td>"
                    f"<td>{e(rng)}</td><td>{_fmt(start, 6)}</td>"
                    f"<td>{_fmt(p['best'], 6)}</td><td>{moved}</td><td>{edge}</td></tr>")
    figs, tfig = data["best_figures"], data.get("target_figures") or {}
    frows = []
    for key, label, unit in (("light_output_ratio", "light output ratio", ""),
                             ("luminous_flux", "flux", "lm"),
                             ("peak_intensity", "peak intensity", "cd"),
                             ("beam_angle_c0_c180", "beam angle C0-C180", "deg"),
                             ("beam_angle_c90_c270", "beam angle C90-C270", "deg"),
                             ("field_angle_c0_c180", "field angle C0-C180", "deg"),
                             ("field_angle_c90_c270", "field angle C90-C270", "deg")):
        v, s = figs.get(key), figs.get(f"{key}_error")
        best = "-" if v is None else f"{v:.4g} &plusmn; {s:.2g} {unit}" if s is not None \
            else f"{v:.4g} {unit}"
        frows.append(f"<tr><td>{label}</td><td>{best}</td>"
                     f"<td>{_fmt(tfig.get(key))}</td></tr>")
    def met(t) -> str:
        return "" if t["met"] is None else "met" if t["met"] else "<b>not met</b>"

    trows = "".join(f"<tr><td><code>{e(t['term'])}</code></td><td>{_fmt(t['value'])}</td>"
                    f"<td>{_fmt(t['error'], 2)}</td><td>{met(t)}</td></tr>"
                    for t in data.get("terms", []))
    captions = {"merit": "the merit of every candidate, with its standard error, against "
                         "evaluations and seconds",
                "polar": "the target and the best, in both planes",
                "parameters": "how far each parameter moved within its range",
                "profile": "the profile, as it started and as fitted"}
    pics = "".join(f'<figure><img src="{e(f)}" alt="{e(captions.get(k, k))}"><figcaption>'
                   f"{e(captions.get(k, k))}</figcaption></figure>"
                   for k, f in images.items())
    target = data.get("target")
    tgt = ""
    if target:
        how = "in candela" if data["objective"]["absolute"] else \
            "by shape (each distribution in cd/klm of its own flux)"
        tgt = (f"<p>Target <code>{e(target['file'])}</code> ({e(target['symmetry'])} "
               f"symmetry), compared {how}.</p>")
    floor = (f"; a perfect candidate would show {data['noise_floor']:.2g} at these photons"
             if data.get("match") is not None else "")
    terms = ("<h2>Terms and constraints</h2><table><tr><th>term</th><th>value</th>"
             f"<th>error</th><th></th></tr>{trows}</table>") if trows else ""
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<title>lumitrace fit: {e(data['stage'])}</title><style>{_CSS}</style></head>
<body><h1>Fit of <code>{e(data['stage'])}</code></h1>
{tgt}
<p><b>Merit {data['merit']:.4g} &plusmn; {data['merit_error']:.2g}</b> (the best traced
again with seed {data['final_seed']}, {data['final_photons']:,} photons{floor}).
In the search: {data['search_merit']:.4g} &plusmn; {data['search_merit_error']:.2g} at
{data['search_photons']:,} photons. {data['evaluations']} evaluations in
{data['generations']} generations, {data['seconds']:.1f} s ({e(data['stopped'])}).</p>
<p>Edits layer: <code>{e(data['edits'])}</code> (<code>lumitrace trace STAGE --edits
LAYER</code> composes it; <code>lumitrace edits merge STAGE --layer LAYER</code> keeps it).</p>
<h2>Parameters</h2>
<table><tr><th>parameter</th><th>prim</th><th>range</th><th>start</th><th>best</th>
<th>moved</th><th></th></tr>
{''.join(rows)}</table>
{terms}
<h2>Figures</h2>
<table><tr><th>figure</th><th>best (&plusmn; standard error)</th><th>target</th></tr>
{''.join(frows)}</table>
<h2>Pictures</h2>{pics or '<p>(not drawn)</p>'}
</body></html>
"""
