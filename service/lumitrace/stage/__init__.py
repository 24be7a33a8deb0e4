"""Stage reading (USD -> :class:`~lumitrace.scene.Scene`) and its validation rules."""
from __future__ import annotations

from ..scene.shaping import shaping_fraction
from .lights import light_flux
from .materials import luminance, preview_surface_values
from .reader import read_stage, scene_from_stage

__all__ = ["read_stage", "scene_from_stage", "light_flux", "luminance",
           "preview_surface_values", "shaping_fraction"]
