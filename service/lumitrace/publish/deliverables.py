"""The deliverables a run writes on request (``lumitrace trace --deliverables``): the
datasheet (HTML and PDF) and the GLDF container, from the same result record and grid as
the photometric files, into the run's transaction beside them."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Mapping

from ..atomic import atomic_path, write_text
from ..filenames import DATASHEET_HTML_SUFFIX, DATASHEET_PDF_SUFFIX, GLDF_SUFFIX
from ..photometry.distribution import Photometry
from ..scene import Scene

if TYPE_CHECKING:
    from .datasheet import DatasheetInput

# The writers are imported when a deliverable is written: every run imports this module
# for the paths, and the XML escaping (xml.sax) loads urllib, http and ssl (20 ms).

#: Output keys of the deliverables (record fields of :data:`lumitrace.schema.RESULT_FIELDS`).
DELIVERABLES = ("datasheet_html", "datasheet_pdf", "gldf")


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(data)


def deliverable_paths(out_dir: str | Path, name: str) -> dict[str, Path]:
    """Where the deliverables of ``NAME`` go in ``out_dir``."""
    out = Path(out_dir)
    return {"datasheet_html": out / f"{name}{DATASHEET_HTML_SUFFIX}",
            "datasheet_pdf": out / f"{name}{DATASHEET_PDF_SUFFIX}",
            "gldf": out / f"{name}{GLDF_SUFFIX}"}


def write_datasheet(data: DatasheetInput, html_path: Path, pdf_path: Path,
                    polar_png: bytes | None = None) -> None:
    """Write the datasheet's HTML page and PDF (``polar_png``: the polar curve already
    drawn for this record, else drawn here)."""
    from .datasheet import curve_pngs, datasheet_html
    from .datasheet_pdf import datasheet_pdf

    curves = curve_pngs(data, polar=polar_png is None)
    if polar_png is not None:
        curves = {"polar": polar_png, **curves}
    write_text(html_path, datasheet_html(data, curves))
    write_bytes(pdf_path, datasheet_pdf(data))


def write_deliverables(scene: Scene, ph: Photometry, record: Mapping,
                       staged: Mapping[str, Path], final: Mapping[str, Path],
                       run_id: str = "") -> None:
    """Write the datasheet and the GLDF container to ``staged`` paths (the transaction's;
    ``final`` names the files as published, which the container's entries follow). The
    LDT, IES and pictures are read from ``staged``, as this run wrote them."""
    from .datasheet import DatasheetInput
    from .datasheet_content import luminaire_name
    from .gldf import GldfFiles, gldf_bytes
    from .l3d import l3d_bytes

    def png(key):
        path = staged.get(key)
        return Path(path).read_bytes() if path and Path(path).is_file() else None

    solid_png, polar_png = png("photometric_solid"), png("polar_diagram")
    data = DatasheetInput(record, ph.grid, scene.info, solid_png, run_id,
                          png("colour_diagram"))
    write_datasheet(data, staged["datasheet_html"], staged["datasheet_pdf"], polar_png)
    name = luminaire_name(record, scene.info)
    files = GldfFiles(
        ldt=(final["ldt"].name, Path(staged["ldt"]).read_bytes()),
        ies=(final["ies"].name, Path(staged["ies"]).read_bytes()),
        l3d=(final["gldf"].with_suffix(".l3d").name, l3d_bytes(scene, ph.opening, name)),
        pdf=(final["datasheet_pdf"].name, Path(staged["datasheet_pdf"]).read_bytes()),
        png=None if solid_png is None else (final["photometric_solid"].name, solid_png))
    write_bytes(staged["gldf"], gldf_bytes(record, scene.info, files, name))
