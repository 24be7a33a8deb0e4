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


def _curves(grid: dict) -> list[tuple[list[float] | None, list[float] | None]]:
    """The (right, left) half-planes of C0-C180 and C90-C270 (cd)."""
    return [(_plane(grid, a), _plane(grid, b)) for a, b in ((0, 180), (90, 270))]


def grid_peak(grid: dict) -> float:
    """The largest intensity (cd) the polar curve of ``grid`` draws."""
    return max((max(p) for pair in _curves(grid) for p in pair if p), default=0.0)


def polar_svg(grid: dict, size: int = 220, peak: float | None = None,
              css: str = "") -> str:
    """The polar curve of a photometry file's grid as SVG: nadir down, C0 and C90 to the
    right, C180 and C270 to the left, with rings labelled in cd, scaled to ``peak`` (cd;
    None: the curve's own peak)."""
    gam = [math.radians(float(g)) for g in grid["gamma"]]
    curves = _curves(grid)
    peak = peak or grid_peak(grid) or 1.0
    r0, mid = size * 0.45, size / 2
    rings = _ticks(peak)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{size}" '
             f'viewBox="0 0 {size} {size}"{css}>',
             *[f'<circle cx="{mid}" cy="{mid}" r="{r0 * t / peak:.1f}" fill="none" '
               f'stroke="#ddd"/>' for t in rings],
             f'<line x1="{mid}" y1="{mid - r0}" x2="{mid}" y2="{mid + r0}" stroke="#ddd"/>',
             *[f'<text x="{mid - 2}" y="{mid - r0 * t / peak + 9:.1f}" font-size="8" '
               f'fill="#999" text-anchor="end">{t:g}</text>' for t in rings]]
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


def _ticks(peak: float) -> list[float]:
    """Up to four round ring values (cd) at or below ``peak``."""
    raw = peak / 4
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw)
    return [step * k for k in range(1, 5) if step * k <= peak * 1.0001]


def _pm(v, e, digits=1) -> str:
    if v is None:
        return "-"
    return f"{v:.{digits}f}" + ("" if e is None else f" &plusmn; {e:.{digits}f}")


#: The figures the overview's table of differences compares: (key, label, "relative"
#: (percent of the chosen case) or "absolute", unit).
DIFFERENCES = (("luminous_flux", "flux", "relative", "%"),
               ("light_output_ratio", "LOR", "relative", "%"),
               ("peak_intensity", "peak", "relative", "%"),
               ("beam_angle_c0_c180", "beam C0-C180", "absolute", "deg"),
               ("beam_angle_c90_c270", "beam C90-C270", "absolute", "deg"),
               ("field_angle_c0_c180", "field C0-C180", "absolute", "deg"),
               ("field_angle_c90_c270", "field C90-C270", "absolute", "deg"),
               ("ugr_4h8h_70_50_20", "UGR 4H8H", "absolute", ""))

#: The overview's script: the scale toggle and the table of differences against a chosen
#: case (each difference with the combined standard error of both, and whether it lies
#: within two of them: the noise).
_SCRIPT = r"""
const data = JSON.parse(document.getElementById("sweep-data").textContent);
const own = document.getElementById("own-scale");
function scale() { document.body.classList.toggle("own", own.checked); }
own.addEventListener("change", scale);
scale();
function diff(a, ea, b, eb, kind) {
  if (a == null || b == null) return null;
  const known = ea != null && eb != null;
  if (kind === "relative") {
    if (!(b > 0)) return null;
    return { value: 100 * (a / b - 1), error: known ? 100 * Math.hypot(ea, a * eb / b) / b : null };
  }
  return { value: a - b, error: known ? Math.hypot(ea, eb) : null };
}
function show(d, unit) {
  if (!d) return "-";
  const e = d.error, n = e > 0 ? Math.min(4, Math.max(0, 1 - Math.floor(Math.log10(e)))) : 2;
  const v = Math.abs(d.value).toFixed(n), sign = Number(v) === 0 ? "" : d.value > 0 ? "+" : "-";
  return sign + v + (e == null ? " ± ?" : " ± " + e.toFixed(n)) + (unit ? " " + unit : "");
}
const pick = document.getElementById("reference");
function table() {
  const ref = data.cases[Number(pick.value)];
  const head = "<tr><th>case</th>" + data.figures.map((f) => `<th>${f[1]}</th>`).join("") + "<th></th></tr>";
  const rows = data.cases.map((c, i) => {
    if (i === Number(pick.value)) return "";
    let beyond = 0, decided = 0;
    const cells = data.figures.map(([k, , kind, unit]) => {
      const d = diff(c.figures[k], c.figures[k + "_error"], ref.figures[k], ref.figures[k + "_error"], kind);
      const within = d && d.error != null ? Math.abs(d.value) <= 2 * d.error : null;
      if (within != null) { decided++; if (!within) beyond++; }
      return `<td class="${within === false ? "beyond" : within ? "within" : ""}" data-key="${k}">${show(d, unit)}</td>`;
    }).join("");
    const verdict = !decided ? "" : beyond ? `${beyond} beyond the noise` : "all within the noise";
    return `<tr data-case="${i}"><td>${c.label}</td>${cells}<td class="verdict">${verdict}</td></tr>`;
  }).join("");
  document.getElementById("differences").innerHTML = head + rows;
}
pick.addEventListener("change", table);
table();
"""


def _case_data(r: dict) -> dict:
    keys = [k for f in DIFFERENCES for k in (f[0], f[0] + "_error")]
    name = Path(r["stage"]).name + (f" {r['variant']}" if r.get("variant") else "")
    return {"label": html.escape(name), "figures": {k: r.get(k) for k in keys}}


def overview(rows: list[dict], out: Path) -> str:
    """The overview page: a card per case with its polar curve (on one scale for all cases,
    or each on its own: a toggle) and figures, and a table of every case's differences
    from a chosen one."""
    grids = []
    for r in rows:
        try:
            grid = None if r.get("error") else \
                json.loads(Path(r["photometry_data"]).read_text())
            if grid is not None:
                grid_peak(grid)
            grids.append(grid)
        except (OSError, ValueError, KeyError, TypeError, IndexError):
            grids.append(None)
    common = max((grid_peak(g) for g in grids if g is not None), default=0.0) or None
    cards = []
    for r, grid in zip(rows, grids):
        if r.get("error"):
            cards.append(f'<div class="card failed"><h2>{html.escape(Path(r["stage"]).name)}'
                         f'</h2><h3>{html.escape(r["variant"] or "as composed")}</h3>'
                         f'<p>failed: {html.escape(r["error"])}</p></div>')
            continue
        svg = "<p>(no photometry file)</p>" if grid is None else \
            polar_svg(grid, peak=common, css=' class="common"') + \
            polar_svg(grid, css=' class="own"')
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
    data = json.dumps({"cases": [_case_data(r) for r in rows],
                       "figures": [list(f) for f in DIFFERENCES]}).replace("</", "<\\/")
    options = "".join(f'<option value="{i}">{c["label"]}</option>'
                      for i, c in enumerate(_case_data(r) for r in rows))
    return ("<!doctype html><html><head><meta charset='utf-8'><title>lumitrace sweep"
            "</title><style>body{font-family:sans-serif}.card{display:inline-block;"
            "vertical-align:top;margin:8px;padding:8px;border:1px solid #ccc;width:240px;"
            "font-size:12px}.failed{border-color:#c00}h2,h3{font-size:13px;margin:2px 0}"
            "svg.own{display:none}"
            "body.own svg.own{display:inline}body.own svg.common{display:none}"
            "table{border-collapse:collapse;font-size:12px}td,th{padding:2px 8px;"
            "border-bottom:1px solid #ddd;text-align:right;white-space:nowrap}"
            "td:first-child,th:first-child{text-align:left}td.beyond{font-weight:bold}"
            "td.within,td.verdict{color:#666}</style></head><body>"
            f"<h1>lumitrace sweep: {len(rows)} cases</h1><p>Polar curves: C0-C180 solid, "
            "C90-C270 dashed, rings in cd. <label><input type='checkbox' id='own-scale'> "
            f"each on its own scale</label> (unticked: one scale for all, {common or 0:.4g} "
            f"cd at the rim). Table: <a href='{CSV}'>{CSV}</a>, <a href='{JSON}'>{JSON}"
            "</a>.</p>" + "".join(cards)
            + "<h2>Differences from <select id='reference'>" + options + "</select></h2>"
            "<p>Each figure minus the chosen case's (flux, LOR and peak in percent of it), "
            "with the combined standard error of both; bold where it lies beyond two of them "
            "(beyond the noise).</p><table id='differences'></table>"
            f"<script type='application/json' id='sweep-data'>{data}</script>"
            f"<script>{_SCRIPT}</script></body></html>\n")
