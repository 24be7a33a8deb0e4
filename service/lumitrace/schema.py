"""Registration of the lumitrace codeless USD schema (applied API schemas) with usd-core."""
from __future__ import annotations

from pathlib import Path

#: Folder holding plugInfo.json and generatedSchema.usda (``schemas/`` of the source tree).
SCHEMA_DIR = Path(__file__).resolve().parents[2] / "schemas"

_registered = False


def register_schema() -> None:
    """Register the schema plugin by absolute path, once, before any stage is composed."""
    global _registered
    if _registered or not (SCHEMA_DIR / "plugInfo.json").exists():
        return
    from pxr import Plug

    Plug.Registry().RegisterPlugins(str(SCHEMA_DIR))
    _registered = True
