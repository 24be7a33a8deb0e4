"""A sweep's results table (``sweep.csv``, ``sweep.json``) and its HTML overview
(``index.html``): one row per stage and variant with its figures and their standard
errors, and each case's polar curve (C0-C180 solid, C90-C270 dashed, cd) drawn as SVG from
its photometry file, so variants compare at a glance with no picture library."""
from __future__ import annotations

import csv
import html
import io
import json
import math
from pathlib import Path

from ..atomic import write_text

CSV, JSON, HTML = "sweep.csv", "sweep.json", "index.html"
#: The figures of a row, each followed by its standard error where it has one.
FIGURES = ("luminous_flux", "light_output_ratio", "peak_intensity", "beam_angle_c0_c180",
           "beam_angle_c90_c270", "field_angle_c0_c180", "field_angle_c90_c270")
COLUMNS = ("stage", "variant", *[k for f in FIGURES for k in (f, f + "_error")],
           "photons", "seconds", "relative_error_bound", "converged", "folder", "error")


def row(case, record, input_hash: str, request: dict, complete: bool, wall: float) -> dict:
    """The table's row of a traced case (``record``: its result record); UGR figures
    are taken where the record computes them."""
    out = {"key": case.key, "stage": str(case.stage), "variant": case.label,
           "variants": dict(case.variants), "folder": str(case.folder)}
    for f in FIGURES:
        out[f], out[f + "_error"] = record[f], record[f + "_error"]
    out.update({k: v for k, v in record.items() if k.startswith("ugr")
                and isinstance(v, (int, float, type(None)))})  # the table's UGR figures
    out.update(photons=record["photons"], seconds=record["seconds"],
               relative_error_bound=record["relative_error_bound"],
               converged=record["converged"], photometry_data=record["photometry_data"],
               input_hash=input_hash, request=request, complete=complete,
               wall_seconds=wall, traced=True)
    return out


def failed_row(case, reason: str) -> dict:
    """The table's row of a case that failed: the case and why (no figures)."""
    return {"key": case.key, "stage": str(case.stage), "variant": case.label,
            "variants": dict(case.variants), "folder": str(case.folder), "error": reason,
            "complete": False}


def write(out: Path, rows: list[dict]) -> None:
    """The CSV and JSON tables and the HTML overview, each written atomically."""
    write_text(out / JSON, json.dumps({"rows": rows}, indent=1) + "\n")
    extra = sorted({k for r in rows for k in r if k.startswith("ugr")})
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*COLUMNS, *extra])
    for r in rows:
        w.writerow(["" if r.get(c) is None else r.get(c) for c in (*COLUMNS, *extra)])
    write_text(out / CSV, buf.getvalue())
    write_text(out / HTML, overview(rows, out))


def _plane(grid: dict, c: float) -> list[float] | None:
    """The intensities (cd) of C plane ``c``, from the grid's planes or their symmetry."""
    cs = [float(x) for x in grid["c"]]
    for cand in (c, (360 - c) % 360, (180 - c) % 360, (180 + c) % 360):
        for i, x in enumerate(cs):
            if abs(x - cand) < 1e-6:
                return grid["candela"][i]
    return grid["candela"][0] if len(cs) == 1 else None


def polar_svg(grid: dict, size: int = 220) -> str:
    """The polar curve of a photometry file's grid as SVG: nadir down, C0 and C90 to the
    right, C180 and C270 to the left, scaled to the peak."""
    gam = [math.radians(float(g)) for g in grid["gamma"]]
    curves = [(_plane(grid, a), _plane(grid, b)) for a, b in ((0, 180), (90, 270))]
    peak = max((max(p) for pair in curves for p in pair if p), default=0.0) or 1.0
    r0, mid = size * 0.45, size / 2
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{size}" '
             f'viewBox="0 0 {size} {size}">',
             *[f'<circle cx="{mid}" cy="{mid}" r="{r0 * k / 4:.1f}" fill="none" '
               f'stroke="#ddd"/>' for k in (1, 2, 3, 4)],
             f'<line x1="{mid}" y1="0" x2="{mid}" y2="{size}" stroke="#ddd"/>']
    for (right, left), dash in zip(curves, ("", ' stroke-dasharray="4 3"')):
        if right is None or left is None:
            continue
        pts = [(mid - r0 * i / peak * math.sin(g), mid + r0 * i / peak * math.cos(g))
               for i, g in zip(reversed(left), reversed(gam))]
        pts += [(mid + r0 * i / peak * math.sin(g), mid + r0 * i / peak * math.cos(g))
                for i, g in zip(right, gam)]
        d = " ".join(f"{x:.1f},{y:.1f}" for x, y in pts)
        parts.append(f'<polyline points="{d}" fill="none" stroke="#c50"{dash}/>')
    parts.append(f'<text x="4" y="14" font-size="11">{peak:.4g} cd</text></svg>')
    return "".join(parts)


def _pm(v, e, digits=1) -> str:
    if v is None:
        return "-"
    return f"{v:.{digits}f}" + ("" if e is None else f" &plusmn; {e:.{digits}f}")


def overview(rows: list[dict], out: Path) -> str:
    """The overview page: a card per case with its polar curve and figures."""
    cards = []
    for r in rows:
        if r.get("error"):
            cards.append(f'<div class="card failed"><h2>{html.escape(Path(r["stage"]).name)}'
                         f'</h2><h3>{html.escape(r["variant"] or "as composed")}</h3>'
                         f'<p>failed: {html.escape(r["error"])}</p></div>')
            continue
        try:
            grid = json.loads(Path(r["photometry_data"]).read_text())
            svg = polar_svg(grid)
        except (OSError, ValueError, KeyError, TypeError, IndexError):
            svg = "<p>(no photometry file)</p>"
        folder = Path(r["folder"])
        link = folder.relative_to(out) if folder.is_relative_to(out) else folder
        lines = [f"flux {_pm(r['luminous_flux'], r['luminous_flux_error'])} lm",
                 f"LOR {_pm(r['light_output_ratio'], r['light_output_ratio_error'], 4)}",
                 f"peak {_pm(r['peak_intensity'], r['peak_intensity_error'])} cd",
                 f"beam {_pm(r['beam_angle_c0_c180'], r['beam_angle_c0_c180_error'])} / "
                 f"{_pm(r['beam_angle_c90_c270'], r['beam_angle_c90_c270_error'])} deg",
                 f"field {_pm(r['field_angle_c0_c180'], r['field_angle_c0_c180_error'])} / "
                 f"{_pm(r['field_angle_c90_c270'], r['field_angle_c90_c270_error'])} deg",
                 f"{r['photons']:,} photons, {r['seconds']:.1f} s"
                 + (", converged" if r["converged"] else "")
                 + ("" if r.get("complete", True) else ", incomplete")]
        cards.append(
            f'<div class="card"><h2>{html.escape(Path(r["stage"]).name)}</h2>'
            f'<h3>{html.escape(r["variant"] or "as composed")}</h3>{svg}'
            + "".join(f"<div>{x}</div>" for x in lines)
            + f'<div><a href="{html.escape(str(link))}/">outputs</a></div></div>')
    return ("<!doctype html><html><head><meta charset='utf-8'><title>lumitrace sweep"
            "</title><style>body{font-family:sans-serif}.card{display:inline-block;"
            "vertical-align:top;margin:8px;padding:8px;border:1px solid #ccc;width:240px;"
            "font-size:12px}.failed{border-color:#c00}h2,h3{font-size:13px;margin:2px 0}"
            "</style></head><body>"
            f"<h1>lumitrace sweep: {len(rows)} cases</h1><p>Polar curves: C0-C180 solid, "
            f"C90-C270 dashed, each scaled to its own peak. Table: <a href='{CSV}'>{CSV}</a>, "
            f"<a href='{JSON}'>{JSON}</a>.</p>" + "".join(cards) + "</body></html>\n")
