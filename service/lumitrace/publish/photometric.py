"""The photometric files of a result: IES LM-63-2019, EULUMDAT, the grid and figures with
their standard errors as JSON, and the two pictures."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

from ..atomic import write_text
from ..filenames import (COLOUR_DIAGRAM_SUFFIX, COLOUR_SUFFIX, IES_SUFFIX, LDT_SUFFIX,
                         PHOTOMETRY_SUFFIX, POLAR_SUFFIX, SOLID_SUFFIX)
from ..photometry.diagrams import photometric_solid, polar_diagram, submit_solid
from ..photometry.colour import ColourOverAngle
from ..photometry.distribution import Photometry
from ..photometry.eulumdat import write_ldt
from ..photometry.lm63 import write_ies
from ..scene import Scene
from .record import defined
from .transaction import signals_held


def photometric_paths(out_dir: str | Path, name: str) -> dict[str, Path]:
    """Where the photometric files of ``NAME`` go in ``out_dir``."""
    out = Path(out_dir)
    return {"ies": out / f"{name}{IES_SUFFIX}", "ldt": out / f"{name}{LDT_SUFFIX}",
            "photometry_data": out / f"{name}{PHOTOMETRY_SUFFIX}",
            "polar_diagram": out / f"{name}{POLAR_SUFFIX}",
            "photometric_solid": out / f"{name}{SOLID_SUFFIX}",
            "colour_data": out / f"{name}{COLOUR_SUFFIX}",
            "colour_diagram": out / f"{name}{COLOUR_DIAGRAM_SUFFIX}"}


def photometry_json(ph: Photometry, run_id: str = "") -> str:
    """The published grid (cd) with the standard error of every value, its symmetry, the
    figures with theirs and the luminous opening, as JSON text."""
    g = ph.grid
    doc = {
        "definition": "each intensity is a point value at its gamma: the value there of a "
                      "parabola fitted to the photon flux per solid angle in 0.25 deg gamma "
                      "bins around it (to its nearer neighbour, at least three bins each "
                      "side), within its C cell (C +- half the C step, whose mean it is); "
                      "at gamma 0 and 180 an even parabola's over the polar cap of "
                      "poleCaps_deg, all C; sigma is its standard error (binomial, analog "
                      "photons, exact for the fit's fixed weights)",
        "frame": "type C: gamma from nadir (the luminaire's -up), C counter-clockwise from "
                 "its +X seen from above",
        "runId": run_id,
        "units": {"c": "deg", "gamma": "deg", "candela": "cd", "sigma": "cd"},
        "symmetry": g.symmetry,
        "symmetrySource": ph.symmetry.source,
        "symmetrySettled": ph.symmetry.settled,
        "symmetryAveraged": ph.symmetry.name,
        "poleCaps_deg": None if g.pole_caps is None else list(g.pole_caps),
        "symmetryDepartures": {name: {"estimate": b[0], "lower": b[1], "upper": b[2]}
                               for name, b in ph.symmetry.departures.items()},
        "c": g.c.tolist(), "gamma": g.gamma.tolist(),
        "candela": g.candela.tolist(), "sigma": g.sigma.tolist(),
        "figures": {k: defined(v) for k, v in ph.figures.as_dict().items()},
        "luminousOpening": {"length_m": ph.opening.length, "width_m": ph.opening.width,
                            "height_m": ph.opening.height},
    }
    return json.dumps(doc, indent=1) + "\n"


def write_photometric_files(scene: Scene, ph: Photometry, paths: dict[str, Path], name: str,
                            pictures: bool = True, run_id: str = "",
                            cct_K: float | None = None,
                            checkpoint: Callable[[], None] = lambda: None) -> None:
    """Write the IES and LDT files, the JSON of the grid and figures with their errors
    (and, with ``pictures``, the polar curve and the photometric solid) of ``ph`` to
    ``paths`` (see :func:`photometric_paths`). The luminaire's own data (``scene.info``)
    and ``cct_K`` (the traced colour's CCT, where the stage has colour) go into both
    files; a round opening is written as round. ``checkpoint`` runs before each picture
    (it may raise to abandon the write)."""
    fig, opening, grid, lamp = ph.figures, ph.opening, ph.grid, ph.lamp_flux
    info = scene.info
    luminaire = scene.luminaire_path.rsplit("/", 1)[-1] or name
    err = fig.photometry_error
    lights = sum(len(e.light_paths) for e in scene.emitters)
    lamps = info.lamp or f"{lights} UsdLux emitter(s), {lamp:.6g} lm"
    keywords = {"MANUFAC": info.manufacturer,
                "LUMCAT": info.catalogue_number or name,
                "LUMINAIRE": info.name or f"{luminaire} ({Path(scene.stage_path).name})",
                "LAMP": lamps,
                "FILEGENINFO": "computed by photon tracing from the USD stage; point values "
                               "in gamma (parabolas fitted to 0.25 deg bins of photon "
                               "counts), means over each C plane's cell; relative RMS "
                               "standard error "
                               f"{'n/a' if err is None else f'{err:.2%}'} (per value in "
                               f"{paths['photometry_data'].name}); "
                               f"symmetry {ph.symmetry.describe()}",
                "_LUMITRACE_RUN": run_id}
    if cct_K is not None:
        keywords["_CCT"] = f"{cct_K:.0f} K"
    if info.colour_rendering_index is not None:
        keywords["_CRI"] = f"{info.colour_rendering_index:g}"
    write_text(paths["photometry_data"], photometry_json(ph, run_id))
    sign = -1.0 if opening.round else 1.0  # LM-63: negative width and length, round
    write_ies(paths["ies"], grid, lamp, sign * opening.width, sign * opening.length,
              opening.height, keywords, info.input_power_w or 0.0)
    box = opening.box
    round_area = opening.round and abs(opening.length - opening.width) <= \
        0.02 * max(opening.length, opening.width)  # a circle: its diameter and width 0
    # EULUMDAT's length runs along the C90-C270 plane (the C0-C180 plane is across a linear
    # luminaire), its width along C0-C180: our extents along C90 and C0, in that order
    mm = {"length": 1000 * box[1], "width": 1000 * box[0], "height": 1000 * box[2],
          "lum_length": 1000 * (0.5 * (opening.length + opening.width) if round_area
                                else opening.width),
          "lum_width": 0.0 if round_area else 1000 * opening.length,
          "lum_height": 1000 * opening.height}
    write_ldt(paths["ldt"], grid, lamp, info.name or luminaire, mm,
              fig.downward_flux_fraction, fig.light_output_ratio,
              company=info.manufacturer or "lumitrace",
              # the run id first: the field is cut at 78 characters
              report=f"lumitrace run {run_id}: {name}; symmetry {ph.symmetry.source}",
              number=info.catalogue_number, file_name=paths["ldt"].name,
              lamp_type=info.lamp or "lumitrace emitters",
              colour="" if cct_K is None else f"{cct_K:.0f} K",
              cri="" if info.colour_rendering_index is None  # its 6 characters
              else f"{round(info.colour_rendering_index, 2):g}",
              watts=info.input_power_w or 0.0)
    if pictures:
        title = f"{info.name or luminaire}: {fig.luminous_flux:.0f} lm, " \
                f"LOR {fig.light_output_ratio:.2f}"
        checkpoint()
        # the renderer process (where the process started one) draws the solid meanwhile,
        # into a folder of its own: abandoned here, it never reaches this set
        job = submit_solid(paths["photometric_solid"], grid, scene, title)
        polar_diagram(paths["polar_diagram"], grid, lamp, title, fig.as_dict())
        checkpoint()
        # VTK does not survive a Python exception raised inside it by a signal handler:
        # a signal waits until the picture is drawn
        with signals_held():
            photometric_solid(paths["photometric_solid"], grid, scene, title, job)


def write_colour_files(col: ColourOverAngle, paths: dict[str, Path], name: str,
                       pictures: bool = True, run_id: str = "", title: str = "",
                       checkpoint: Callable[[], None] = lambda: None) -> None:
    """Write the colour over angle as JSON and, with ``pictures``, its diagram (titled
    ``title``, the luminaire's name, else ``name``; ``checkpoint`` runs before it)."""
    write_text(paths["colour_data"], json.dumps({"runId": run_id, **col.table()}, indent=1)
               + "\n")
    if pictures:
        from ..photometry.diagrams import colour_diagram

        checkpoint()
        colour_diagram(paths["colour_diagram"], col, title or name)
