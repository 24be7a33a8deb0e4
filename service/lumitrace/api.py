"""The Python API: what a DCC's embedded Python (or a pipeline script) calls to trace a
luminaire it has open and write the results for it. Every name here is a stable entry point;
the modules behind them are the implementation.

    import lumitrace.api as lt
    scene = lt.scene_from_stage(stage)               # a live Usd.Stage, unsaved edits included
    result = lt.trace(scene, lt.TraceSettings(target_error=0.02))
    record = lt.write_results(result, "/shots/lamp/lighting")
    record["ies"], record["peak_intensity"], record["peak_intensity_error"]
    colour = lt.colour_over_angle(result.accumulator)  # None for a stage without colour
"""
from __future__ import annotations

from .photometry.colour import ColourOverAngle, colour_over_angle
from .photometry.distribution import Photometry, photometry_of
from .publish.check import Check, check_stage
from .publish.outputs import write_outputs as write_results
from .publish.record import ResultRecord
from .run.session import Progress, TraceResult
from .run.session import run as trace
from .run.settings import TraceSettings
from .scene import Scene
from .stage.reader import read_stage, scene_from_stage

__all__ = ["Check", "ColourOverAngle", "Photometry", "Progress", "ResultRecord", "Scene",
           "TraceResult", "TraceSettings", "check_stage", "colour_over_angle", "photometry_of",
           "read_stage", "scene_from_stage", "trace", "write_results"]
