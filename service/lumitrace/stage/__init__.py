"""Stage reading (USD -> :class:`~lumitrace.scene.Scene`) and its validation rules.

The names below load USD with their modules, when first asked for: the package's
pxr-free modules (:mod:`.validate`, :mod:`.usda_scan`, :mod:`.scene_cache`) are imported
without it.
"""
from __future__ import annotations

import importlib

#: Each name this package gives, and the module that holds it.
_HOMES = {"read_stage": ".reader", "scene_from_stage": ".reader", "light_flux": ".lights",
          "luminance": ".materials", "preview_surface_values": ".materials",
          "shaping_fraction": "..scene.shaping"}

__all__ = list(_HOMES)


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(home, __name__), name)
    globals()[name] = value
    return value
