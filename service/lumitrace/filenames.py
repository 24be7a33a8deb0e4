"""The names of the files a run writes for a stage ``NAME.<ext>``: one place for them, so
the stage reader recognises our own result layer and the writers agree on every name."""
from __future__ import annotations

import os
from pathlib import Path

#: Suffix of the result layer, sublayered into the stage: ``NAME.lumitrace.usda``.
RESULT_LAYER_SUFFIX = ".lumitrace.usda"
#: Suffix of the edits layer holding a service's accepted scene deltas:
#: ``NAME.lumitrace-edits.usda``, beside the stage, applied over it as its session layer.
EDITS_LAYER_SUFFIX = ".lumitrace-edits.usda"
#: Output suffixes after ``NAME`` (the result layer lives beside the stage).
INTENSITY_SUFFIX = ".intensity.exr"
LATLONG_SUFFIX = ".latlong.exr"
IES_SUFFIX = ".ies"
LDT_SUFFIX = ".ldt"
POLAR_SUFFIX = ".polar.png"
SOLID_SUFFIX = ".solid.png"
PHOTOMETRY_SUFFIX = ".photometry.json"
COLOUR_SUFFIX = ".colour.json"
COLOUR_DIAGRAM_SUFFIX = ".colour.png"
#: The deliverables, written on request: the datasheet (HTML, PDF) and the GLDF container.
DATASHEET_HTML_SUFFIX = ".datasheet.html"
DATASHEET_PDF_SUFFIX = ".datasheet.pdf"
GLDF_SUFFIX = ".gldf"
#: The record of the datasheet ``lumitrace datasheet`` writes (its files, its stage).
DATASHEET_RECORD_SUFFIX = ".datasheet.json"
#: Every file a trace (or ``lumitrace datasheet``) may write for ``NAME`` in its output
#: folder: the only names an interrupted publishing may be completed onto, and the files
#: a run may replace.
OUTPUT_SUFFIXES = (INTENSITY_SUFFIX, LATLONG_SUFFIX, IES_SUFFIX, LDT_SUFFIX, POLAR_SUFFIX,
                   SOLID_SUFFIX, PHOTOMETRY_SUFFIX, COLOUR_SUFFIX, COLOUR_DIAGRAM_SUFFIX,
                   DATASHEET_HTML_SUFFIX, DATASHEET_PDF_SUFFIX, GLDF_SUFFIX, RESULT_LAYER_SUFFIX,
                   DATASHEET_RECORD_SUFFIX)


def output_names(name: str) -> set[str]:
    """The file names a trace of stage ``NAME`` may write in its output folder."""
    return {name + suffix for suffix in OUTPUT_SUFFIXES}


def stage_name(stage_path: str | os.PathLike) -> str:
    """``NAME`` of ``NAME.usda`` (the stage file name without its last extension)."""
    return Path(stage_path).name.rsplit(".", 1)[0]


def result_layer_path(stage_path: str | os.PathLike) -> Path:
    """``NAME.lumitrace.usda`` beside the stage ``NAME.<ext>``."""
    stage = Path(stage_path)
    return stage.with_name(stage_name(stage) + RESULT_LAYER_SUFFIX)


def edits_layer_path(stage_path: str | os.PathLike) -> Path:
    """``NAME.lumitrace-edits.usda`` beside the stage ``NAME.<ext>``."""
    stage = Path(stage_path)
    return stage.with_name(stage_name(stage) + EDITS_LAYER_SUFFIX)
