"""What the add-on remembers of an imported stage, on the Blender data itself: which prim
each object, material and light came from and what it held then, so that an export or
the live link sends only what the designer changed.

Every record is a hidden ID property (a leading underscore keeps it out of Blender's
custom-property panels) holding plain values:

- ``scene["_lumitrace_stages"]``: one entry per imported stage (its file, default prim,
  metresPerUnit, upAxis);
- ``id["_lumitrace"]`` on objects, materials and lights: the ``stage`` file, the ``prim``
  path, and the imported state (see :mod:`.state`).
"""
from __future__ import annotations

KEY = "_lumitrace"
STAGES_KEY = "_lumitrace_stages"
#: Marks what the live link made (its light, its IES text): never exported.
LIVE_KEY = "_lumitrace_live"


def plain(value):
    """An ID property's value as plain Python (lists, dicts, numbers, text)."""
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if hasattr(value, "to_list"):
        return value.to_list()
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def record(idblock) -> dict | None:
    """The add-on's record of ``idblock`` (an object, material or light), or None."""
    data = idblock.get(KEY) if idblock is not None else None
    return plain(data) if data is not None else None


def stages(scene) -> list[dict]:
    """The stages imported into ``scene``, oldest first."""
    return [plain(s) for s in scene.get(STAGES_KEY, [])]


def add_stage(scene, entry: dict) -> None:
    """Remember an imported stage (replacing an earlier import of the same file)."""
    kept = [s for s in stages(scene) if s["file"] != entry["file"]]
    scene[STAGES_KEY] = kept + [entry]


def stage_entry(scene, file: str | None = None) -> dict:
    """The imported stage ``file`` (default: the one imported last)."""
    known = stages(scene)
    if not known:
        raise LookupError("no lumitrace stage was imported into this scene")
    if file is None:
        return known[-1]
    for entry in known:
        if entry["file"] == file:
            return entry
    raise LookupError(f"the stage {file} was not imported into this scene")
