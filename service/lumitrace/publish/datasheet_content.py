"""What a datasheet says, as sections of table cells built from one result record: the
HTML and the PDF render the same cells, so both show the numbers the files hold.

A cell that shows a figure of the record names it (``key``, with ``value`` the record's
value): the HTML carries both as ``data-key`` and ``data-value`` attributes, which is how a
reader (or a test) ties every number on the page to the record.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from .. import __version__


@dataclass(frozen=True)
class Cell:
    """One table cell: its text, and the record key and value it shows (if any)."""

    text: str
    key: str | None = None
    value: Any = None


@dataclass(frozen=True)
class Section:
    """A titled table: column headers and rows of cells; ``note`` says how to read it."""

    title: str
    header: tuple[str, ...]
    rows: list[list[Cell]] = field(default_factory=list)
    note: str = ""


def digits_for(error: float | None, default: int = 2) -> int:
    """Decimals that show two significant digits of ``error`` (0 to 6)."""
    if error is None or not math.isfinite(error) or error <= 0:
        return default
    return int(min(max(1 - math.floor(math.log10(error)), 0), 6))


def pm(value: float | None, error: float | None, unit: str = "", scale: float = 1.0) -> str:
    """``value +- error unit`` with decimals from the error; "-" where undefined."""
    if value is None or not math.isfinite(value):
        return "-"
    v = value * scale
    e = None if error is None or not math.isfinite(error) else error * scale
    d = digits_for(e)
    text = f"{v:,.{d}f}" + ("" if e is None else f" ± {e:,.{d}f}")
    return text + (f" {unit}" if unit else "")


def figure(record: Mapping, key: str, unit: str = "", scale: float = 1.0,
           error_key: str | None = None) -> Cell:
    """The cell of the record's figure ``key`` with its error (``key + '_error'``)."""
    err = record.get(error_key or f"{key}_error")
    return Cell(pm(record.get(key), err, unit, scale), key, record.get(key))


def luminaire_name(record: Mapping, info) -> str:
    """The name pictures and pages carry: the authored luminaire name, else the prim's."""
    prim = (record.get("luminaire") or "").rstrip("/").rsplit("/", 1)[-1]
    return info.name or prim or "luminaire"


def identity(record: Mapping, info) -> Section:
    """Manufacturer, name, catalogue number, lamp, power, colour rendering."""
    rows = [[Cell("Luminaire"), Cell(luminaire_name(record, info))],
            [Cell("Manufacturer"), Cell(info.manufacturer or "-")],
            [Cell("Catalogue number"), Cell(info.catalogue_number or "-")],
            [Cell("Lamp"), Cell(info.lamp or "-")],
            [Cell("Input power"), Cell("-" if info.input_power_w is None
                                       else f"{info.input_power_w:g} W")],
            [Cell("Colour rendering (Ra)"), Cell("-" if info.colour_rendering_index is None
                                                 else f"{info.colour_rendering_index:g}")]]
    return Section("Luminaire", ("", ""), rows)


def main_figures(record: Mapping, info) -> Section:
    """Flux, LOR, efficacy, peak, beam and field angles, CIE flux code, DFF."""
    r = record
    rows = [[Cell("Luminous flux"), figure(r, "luminous_flux", "lm")],
            [Cell("Lamp flux (emitters)"), Cell(pm(r.get("lamp_flux"), None, "lm"),
                                                "lamp_flux", r.get("lamp_flux"))],
            [Cell("Light output ratio"), figure(r, "light_output_ratio", "%", 100.0)]]
    power = info.input_power_w
    flux, flux_err = r.get("luminous_flux"), r.get("luminous_flux_error")
    if power and flux is not None:
        eff = flux / power
        rows.append([Cell("Luminous efficacy"),
                     Cell(pm(eff, None if flux_err is None else flux_err / power, "lm/W"))])
    peak = r.get("peak_intensity")
    rows.append([Cell("Peak intensity"), figure(r, "peak_intensity", "cd")])
    if peak is not None:
        rows.append([Cell("  at C, gamma"),
                     Cell(f"C {r.get('peak_c') or 0:.1f}°, "
                          f"gamma {r.get('peak_gamma') or 0:.1f}°")])
    for what, level in (("beam", "50%"), ("field", "10%")):
        for plane in ("c0_c180", "c90_c270"):
            label = f"{what.capitalize()} angle ({level}), {plane.replace('_', '-').upper()}"
            rows.append([Cell(label), figure(r, f"{what}_angle_{plane}", "°")])
    values, errors = r.get("cie_flux_code_values"), r.get("cie_flux_code_errors")
    rows.append([Cell("CIE flux code"), Cell(r.get("cie_flux_code") or "-", "cie_flux_code",
                                             r.get("cie_flux_code"))])
    if values:
        rows.append([Cell("  N1..N3 (%)"), Cell(", ".join(
            pm(v, e) for v, e in zip(values[:3], (errors or [None] * 5)[:3])))])
    rows.append([Cell("Downward flux fraction"),
                 figure(r, "downward_flux_fraction", "%", 100.0)])
    rows.append([Cell("Luminous opening (mm)"), opening_cell(r)])
    why = {"declared": "declared", "geometry": "by the geometry",
           "measured": "shown by the counts"}.get(r.get("symmetry_source") or "", "")
    rows.append([Cell("Symmetry of the files"),
                 Cell(f"{r.get('symmetry') or '-'}{f' ({why})' if why else ''}")])
    return Section("Photometric figures (± one standard error)", ("", ""), rows)


def opening_cell(record: Mapping) -> Cell:
    """The luminous opening: length x width x height (mm) with errors, its shape and
    where it comes from; "none" and why where no opening is meaningful."""
    opening = record.get("luminous_opening")
    source = record.get("luminous_opening_source") or "measured"
    if source == "none" or not opening:
        return Cell("none (light leaves from everywhere: declare "
                    "lumitrace:luminousOpening)", "luminous_opening_source", source)
    errors = record.get("luminous_opening_error") or (None, None, None)
    parts = [pm(v, e if source == "measured" and e else None, "", 1000.0)
             for v, e in zip(opening, errors)]
    shape = record.get("luminous_opening_shape") or ""
    return Cell(f"{' x '.join(parts)} ({shape}, {source})", "luminous_opening_source", source)


def not_applicable(title: str, record: Mapping) -> Section:
    """A table the record cannot have: why."""
    return Section(title, ("",), [[Cell("not applicable")]],
                   record.get("luminous_opening_note") or "no luminous opening")


def zonal_section(record: Mapping) -> Section | None:
    """The zonal flux table: lm per 10 deg zone and the cumulative share of the flux."""
    zones = record.get("zonal_flux")
    if not zones:
        return None
    total = sum(z[2] for z in zones) or 1.0
    rows, cum = [], 0.0
    last = max((k for k, z in enumerate(zones) if z[2] > 0), default=0)
    for k, (lo, hi, lm, err) in enumerate(zones):
        cum += lm
        if k > last:  # the dark zones above the last lit one: one row says it
            rows.append([Cell(f"{lo:g}-180°"), Cell("0 (no photon)"), Cell("100.0 %")])
            break
        rows.append([Cell(f"{lo:g}-{hi:g}°"), Cell(pm(lm, err), f"zonal_flux[{k}]", lm),
                     Cell(f"{100 * cum / total:.1f} %")])
    return Section("Zonal flux (from nadir)", ("zone", "flux (lm)", "cumulative"), rows,
                   "from the exact photon counts of the goniometer's cells")


def ugr_section(record: Mapping) -> Section | None:
    """The CIE UGR table (crosswise / endwise per room and reflectance set)."""
    t = record.get("ugr_table")
    if not t:
        return not_applicable("UGR table", record) \
            if record.get("luminous_opening_source") == "none" else None
    refl = list(t["reflectances"])
    rows = []
    for i, room in enumerate(t["rooms_h"]):
        cells = [Cell(f"{room[0]:g}H x {room[1]:g}H")]
        for j in range(len(refl)):
            c, e = t["crosswise"][i][j], t["endwise"][i][j]
            txt = "-" if c is None else f"{c:.1f}/{e:.1f}" if e is not None else f"{c:.1f}"
            cells.append(Cell(txt, f"ugr_table.crosswise[{i}][{j}]", c))
        rows.append(cells)
    cat = pm(record.get("ugr_4h8h_70_50_20"), record.get("ugr_4h8h_70_50_20_error"))
    end = pm(record.get("ugr_4h8h_70_50_20_endwise"),
             record.get("ugr_4h8h_70_50_20_endwise_error"))
    err = max((v for row in t["crosswise_error"] for v in row if v is not None), default=None)
    axis = t.get("long_axis") or ""
    named = (f"crosswise: the luminaire's long axis ({axis}) across the line of sight"
             if axis else "crosswise: the luminaire's C90 axis across the line of sight")
    variation = record.get("ugr_observer_variation")
    if variation:
        rows.append([Cell("observer position, S =")] + [Cell("") for _ in refl])
        for k, s in enumerate(variation["spacing_h"]):
            c, e = variation["crosswise"][k], variation["endwise"][k]
            text = "  ·  ".join(" / ".join("-" if v is None else f"{v:+.1f}" for v in pair)
                                for pair in (c, e))
            rows.append([Cell(f"  {s:g}H"), Cell(text, f"ugr_observer_variation.crosswise[{k}]",
                                                 c)] + [Cell("") for _ in refl[1:]])
    lamp = record.get("ugr_lamp_flux")
    note = (f"crosswise/endwise, spacing {t.get('spacing_h', 0.25):g} H (CIE 117, CIE 190); "
            f"{named}; catalogue 4H 8H 70/50/20: {cat} crosswise, {end} endwise"
            + ("" if err is None else f"; largest standard error of a cell {err:.2f}")
            + ("" if not variation else
               "; observer position: the largest rise / fall (crosswise · endwise) in the "
               "4H 8H room, 70/50/20, as the observer moves along the wall with luminaires "
               "S apart")
            + ("" if lamp is None else
               f"; for {lamp:,.0f} lm of lamps: for lamps of another flux F (the same "
               f"distribution) add 8 log10(F / {lamp:,.0f} lm)"))
    return Section("UGR table", ("room",) + tuple(refl), rows, note)


def luminance_section(record: Mapping) -> Section | None:
    """The luminance table (cd/m2 by C plane and gamma) and the screen-work limits."""
    t = record.get("luminance_table")
    if not t:
        return not_applicable("Luminance (cd/m²)", record) \
            if record.get("luminous_opening_source") == "none" else None
    planes = [k for k, c in enumerate(t["c_deg"]) if float(c) % 45.0 == 0.0 and c < 360]
    rows = []
    for j, g in enumerate(t["gamma_deg"]):
        cells = [Cell(f"{g:g}°")]
        for k in planes:
            v, e = t["cd_per_m2"][k][j], t["error"][k][j]
            cells.append(Cell(pm(v, e), f"luminance_table.cd_per_m2[{k}][{j}]", v))
        rows.append(cells)
    limits = record.get("luminance_screen_limits") or {}
    said = "; ".join(f"{k.replace('_', ' ')}: {v['limit']:g} cd/m² "
                     f"{'met' if v['met'] else 'NOT met'}" for k, v in limits.items())
    note = (f"max at gamma 65-85°: "
            f"{pm(record.get('luminance_screen_max'), record.get('luminance_screen_max_error'))}"
            f" cd/m² (EN 12464-1 screen work; {said})")
    return Section("Luminance (cd/m²)", ("gamma",) + tuple(f"C{t['c_deg'][k]:g}"
                                                         for k in planes), rows, note)


def application_section(record: Mapping) -> Section | None:
    """BUG rating (outdoor, where light goes up or sideways) or the cone diagram."""
    rows = []
    if record.get("bug_rating") and (record.get("upward_flux_fraction") or 0) > 0:
        rows.append([Cell("BUG rating (TM-15-11)"),
                     Cell(f"{record['bug_rating']} (range {record.get('bug_rating_range')}; "
                          f"forward {record.get('bug_forward') or 'C0'})",
                          "bug_rating", record["bug_rating"])])
    cone = record.get("cone_diagram")
    if cone and cone.get("distance_m"):
        for k, d in enumerate(cone["distance_m"]):
            lux = pm(cone["centre_lux"][k], _at(cone, "centre_lux_error", k), "lx")
            beam = pm(_at(cone, "beam_diameter_c0_c180_m", k),
                      _at(cone, "beam_diameter_c0_c180_m_error", k), "m")
            rows.append([Cell(f"{d:g} m"),
                         Cell(f"{lux}, {beam}", f"cone_diagram.centre_lux[{k}]",
                              cone["centre_lux"][k])])
    return Section("Application", ("distance", "centre illuminance, beam Ø C0"), rows,
                   "cone diagram: inverse-square far field") if rows else None


def _at(table: Mapping, key: str, k: int):
    v = table.get(key)
    return v[k] if isinstance(v, list) and k < len(v) else None


def colour_section(record: Mapping) -> Section | None:
    """CCT, Duv and the colour uniformity over angle, for a stage with colour."""
    if record.get("cct_K") is None:
        return None
    rows = [[Cell("CCT"), Cell(f"{record['cct_K']:.0f} K", "cct_K", record["cct_K"])],
            [Cell("Duv"), Cell(f"{record.get('duv'):+.4f}", "duv", record.get("duv"))],
            [Cell("Beam colour spread (Delta u'v')"),
             Cell(f"{record.get('colour_uniformity_duv') or 0:.4f} "
                  f"(noise {record.get('colour_uniformity_noise') or 0:.4f})",
                  "colour_uniformity_duv", record.get("colour_uniformity_duv"))]]
    return Section("Colour", ("", ""), rows)


def provenance(record: Mapping) -> Section:
    """How the figures were computed: photons, seed, errors, version, hashes."""
    r = record
    err, bound = r.get("relative_error"), r.get("relative_error_bound")
    rows = [[Cell("Method"), Cell(f"photon tracing, lumitrace {__version__}")],
            [Cell("Stage, luminaire prim"), Cell(f"{r.get('stage')}, {r.get('luminaire')}")],
            [Cell("Photons traced"), Cell(f"{r.get('photons') or 0:,}", "photons",
                                          r.get("photons"))],
            [Cell("Seed"), Cell(str(r.get("seed")), "seed", r.get("seed"))],
            [Cell("Estimated error of the map (RMS)"),
             Cell("-" if err is None else f"{err:.2%}", "relative_error", err)],
            [Cell("  its upper estimate (bound)"),
             Cell("-" if bound is None else f"{bound:.2%}", "relative_error_bound", bound)],
            [Cell("Error of the files (RMS)"),
             Cell("-" if r.get("photometry_error") is None else
                  f"{r['photometry_error']:.2%}", "photometry_error", r.get("photometry_error"))],
            [Cell("Converged (target)"),
             Cell(f"{'yes' if r.get('converged') else 'no'} "
                  f"({'default' if r.get('target_error') is None else r['target_error']})",
                  "converged", r.get("converged"))],
            [Cell("Input hash"), Cell(str(r.get("input_hash")), "input_hash",
                                      r.get("input_hash"))]]
    return Section("How it was computed", ("", ""), rows,
                   "every figure from the photon counts of the USD stage, with its standard "
                   "error")


def sections(record: Mapping, info) -> tuple[list[Section], list[Section], list[Section]]:
    """The datasheet's sections as (left column, right column, wide tables), each in
    page order; optional ones where the record has their figures."""
    right = (zonal_section(record), colour_section(record), application_section(record))
    wide = (ugr_section(record), luminance_section(record))
    return ([identity(record, info), main_figures(record, info), provenance(record)],
            [s for s in right if s is not None], [s for s in wide if s is not None])
