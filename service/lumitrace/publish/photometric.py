"""The photometric files of a result: IES LM-63-2019, EULUMDAT and the two pictures."""
from __future__ import annotations

from pathlib import Path

from ..filenames import IES_SUFFIX, LDT_SUFFIX, POLAR_SUFFIX, SOLID_SUFFIX
from ..photometry.diagrams import photometric_solid, polar_diagram
from ..photometry.distribution import Photometry
from ..photometry.eulumdat import write_ldt
from ..photometry.lm63 import write_ies
from ..scene import Scene
from .transaction import signals_held


def photometric_paths(out_dir: str | Path, name: str) -> dict[str, Path]:
    """Where the photometric files of ``NAME`` go in ``out_dir``."""
    out = Path(out_dir)
    return {"ies": out / f"{name}{IES_SUFFIX}", "ldt": out / f"{name}{LDT_SUFFIX}",
            "polar_diagram": out / f"{name}{POLAR_SUFFIX}",
            "photometric_solid": out / f"{name}{SOLID_SUFFIX}"}


def write_photometric_files(scene: Scene, ph: Photometry, paths: dict[str, Path], name: str,
                            map_error: float, pictures: bool = True, run_id: str = "") -> None:
    """Write the IES and LDT files (and, with ``pictures``, the polar curve and the
    photometric solid) of ``ph`` to ``paths`` (see :func:`photometric_paths`)."""
    fig, opening, grid, lamp = ph.figures, ph.opening, ph.grid, ph.lamp_flux
    luminaire = scene.luminaire_path.rsplit("/", 1)[-1] or name
    keywords = {"LUMCAT": name, "LUMINAIRE": f"{luminaire} ({Path(scene.stage_path).name})",
                "LAMP": f"{len(scene.emitters)} UsdLux emitter(s), {lamp:.6g} lm",
                "FILEGENINFO": "computed by photon tracing from the USD stage; "
                               f"estimated relative RMS error {map_error:.2%}; "
                               f"symmetry {grid.symmetry}",
                "_LUMITRACE_RUN": run_id}
    write_ies(paths["ies"], grid, lamp, opening.width, opening.length, opening.height, keywords)
    mm = {"length": 1000 * opening.length, "width": 1000 * opening.width,
          "height": 1000 * opening.height, "lum_length": 1000 * opening.length,
          "lum_width": 1000 * opening.width, "lum_height": 1000 * opening.height}
    write_ldt(paths["ldt"], grid, lamp, luminaire, mm, fig.downward_flux_fraction,
              fig.light_output_ratio, report=f"lumitrace {name} run {run_id}".strip())
    if pictures:
        title = f"{luminaire}: {fig.luminous_flux:.0f} lm, LOR {fig.light_output_ratio:.2f}"
        polar_diagram(paths["polar_diagram"], grid, lamp, title)
        # VTK does not survive a Python exception raised inside it by a signal handler:
        # a signal waits until the picture is drawn
        with signals_held():
            photometric_solid(paths["photometric_solid"], grid, scene, title)
