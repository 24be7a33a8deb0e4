"""What the command line prints: the progress of a trace on stderr and the human summary
of a result record."""
from __future__ import annotations

import math
import sys


def progress_bar(total: int | None, seconds: float | None, enabled: bool):
    """A tqdm bar on stderr counting photons (or seconds), with iterations and error; a
    plain line per iteration when stderr is not a terminal (a log file, a farm's capture),
    where a bar's carriage returns would pile up."""
    if not enabled:
        return None, None
    if not sys.stderr.isatty():
        def log(p):
            print(f"iteration {p.iteration}: {p.photons:,} photons, {p.seconds:.1f} s, "
                  f"{shown_error(p)}", file=sys.stderr, flush=True)
        return None, log
    from tqdm import tqdm

    if total is not None:
        bar = tqdm(total=total, unit="ph", unit_scale=True, file=sys.stderr, dynamic_ncols=True)
    elif seconds is not None:
        bar = tqdm(total=round(seconds, 1), unit="s", file=sys.stderr, dynamic_ncols=True,
                   bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s {postfix}")
    else:
        bar = tqdm(unit="ph", unit_scale=True, file=sys.stderr, dynamic_ncols=True)

    def update(p):
        if total is not None:
            bar.update(p.photons - bar.n)
        elif seconds is not None:
            bar.update(min(p.seconds, seconds) - bar.n)
        else:
            bar.update(p.photons - bar.n)
        bar.set_postfix_str(f"it {p.iteration}, {p.photons:.3g} ph, {shown_error(p)}")

    return bar, update


def shown_error(p) -> str:
    """An iteration's error as shown: the files' judged error where the target is judged
    on them, else the map's estimated error (with its bound where that differs)."""
    if p.files is not None and p.estimate is None:
        return f"files' error {pct(p.files.error)}"
    bound = p.estimate.error_bound if p.estimate is not None else None
    text = f"map error {pct(p.relative_error)}"
    if bound is not None and bound != p.relative_error:
        text += f" (at most {pct(bound)})"
    if p.files is not None:
        text += f", files' error {pct(p.files.error)}"
    return text


def pct(value: float | None) -> str:
    """A relative error as a percentage; 'undefined' where there is none (no light)."""
    return "undefined" if value is None or not math.isfinite(value) else f"{value:.2%}"


def pm(value: float | None, error: float | None, unit: str = "", digits: int = 2) -> str:
    """A figure with its standard error: "237.24 cd +- 1.59"; "-" where it is undefined."""
    if value is None:
        return "-"
    return f"{value:.{digits}f}{' ' + unit if unit else ''}" + (
        "" if error is None else f" +- {error:.{digits}f}")


def summary_text(r, stage) -> str:
    """The human summary of a result record."""
    ang = lambda v, e: pm(v, e, "deg", 1)  # noqa: E731
    lines = [
        f"{r.luminaire} in {stage}",
        f"  photons         {r.photons:,} in {r.iterations} iterations, {r.seconds:.2f} s "
        f"({r.photons_per_second:,.0f} photons/s)",
        f"  emitted         {r.emitted_lm:10.2f} lm",
        f"  escaped         {r.escaped_lm:10.2f} lm   (light output ratio "
        f"{pm(r.light_output_ratio, r.light_output_ratio_error, '', 4)})",
        f"  absorbed        {r.absorbed_lm:10.2f} lm"]
    if r.cut_lm:
        lines.append(f"  cut (depth)     {r.cut_lm:10.4f} lm")
    lines += [
        f"  peak intensity  {pm(r.peak_intensity, r.peak_intensity_error, 'cd')} at "
        f"C {r.peak_c:.1f}, gamma {r.peak_gamma:.1f} deg (standard errors after +-)",
        f"  map error       {pct(r.relative_error)} estimated RMS over the sphere, at most "
        f"{pct(r.relative_error_bound)} (raw map {pct(r.raw_relative_error)})"
        f"{', converged' if r.converged and r.target_of == 'map' else ''}"
        + ("" if r.escaped_lm else "   (no light escapes the luminaire)"),
        f"  files' error    {pct(r.photometry_error)} relative RMS standard error of the "
        f"IES/LDT values, worst lit value {pct(r.photometry_worst_error)}"
        f"{', converged' if r.converged and r.target_of == 'files' else ''}",
        f"  downward flux   {r.downward_flux_fraction:.1%}   CIE flux code {r.cie_flux_code}",
        f"  beam angle      {ang(r.beam_angle_c0_c180, r.beam_angle_c0_c180_error)} (C0-C180), "
        f"{ang(r.beam_angle_c90_c270, r.beam_angle_c90_c270_error)} (C90-C270)",
        f"  field angle     {ang(r.field_angle_c0_c180, r.field_angle_c0_c180_error)} "
        f"(C0-C180), {ang(r.field_angle_c90_c270, r.field_angle_c90_c270_error)} (C90-C270)",
        *(f"                  {key.replace('_', ' ')}: - ({why})"
          for key, why in (r.spread_notes or {}).items()),
        f"  symmetry        {r.symmetry} ({_SOURCE.get(r.symmetry_source, '?')})"]
    if r.chromaticity_uv is not None:
        cct = "none (Duv beyond 0.05)" if r.cct_K is None else f"{r.cct_K:.0f} K"
        lines += [
            f"  colour          CCT {cct}, Duv {r.duv:+.4f}, u'v' "
            f"({r.chromaticity_uv[0]:.4f}, {r.chromaticity_uv[1]:.4f})",
            f"  uniformity      Delta u'v' {r.colour_uniformity_duv:.4f} within the beam "
            f"(noise {r.colour_uniformity_noise:.5f})",
            f"  colour files    {r.colour_data}" + (f"  {r.colour_diagram}"
                                                     if r.colour_diagram else "")]
    lines += [
        f"  intensity map   {r.intensity_map}",
        f"  IES / LDT       {r.ies}  {r.ldt}",
        f"  with errors     {r.photometry_data}",
        f"  pictures        {r.polar_diagram}  {r.photometric_solid}" if r.polar_diagram
        else "  pictures        (not drawn)",
        f"  result layer    {r.result_layer}"]
    return "\n".join(lines)


#: How the summary says why the files have their symmetry.
_SOURCE = {"declared": "declared on the stage", "geometry": "shown by the geometry",
           "measured": "shown by the photon counts", "none": "none shown"}
