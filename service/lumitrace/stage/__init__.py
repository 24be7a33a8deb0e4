"""Stage reading (USD -> :class:`~lumitrace.scene.Scene`) and its validation rules."""
from __future__ import annotations

from .reader import (light_flux, luminance, preview_surface_values, read_stage,
                     scene_from_stage, shaping_fraction)

__all__ = ["read_stage", "scene_from_stage", "light_flux", "luminance",
           "preview_surface_values", "shaping_fraction"]
