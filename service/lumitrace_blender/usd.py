"""Blender's own OpenUSD (``pxr``), which Blender ships beside its Python: on its path
inside the Blender application, not on it where Blender runs as the ``bpy`` module."""
from __future__ import annotations

import os
import sys


def pxr_modules():
    """``(Usd, Sdf, UsdGeom, UsdLux, UsdShade, Gf, Vt)`` of the USD that Blender ships."""
    try:
        import pxr  # noqa: F401  (present: Blender's own Python has it on its path)
    except ImportError:
        import bpy
        folder = os.path.join(bpy.utils.resource_path("LOCAL"), "python", "lib",
                              "python%d.%d" % sys.version_info[:2], "site-packages")
        if not os.path.isdir(os.path.join(folder, "pxr")):
            raise ImportError("this Blender ships no OpenUSD Python module (pxr) in "
                              + folder) from None
        sys.path.append(folder)
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt
    return Usd, Sdf, UsdGeom, UsdLux, UsdShade, Gf, Vt
