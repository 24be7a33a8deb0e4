"""What an edit changes, photometrically: the old and the new scene compared.

The kinds, from the cheapest to the dearest to follow: ``none`` (nothing the tracer sees:
names, display colour, prims outside the luminaire, untraced purposes), ``flux`` (emitter
fluxes only: a rescale of their counts, nothing traced), ``emitter`` (an emitter's shape,
shaping or placement), ``material``, ``geometry`` (a part's transform or points) and
``topology`` (emitters or parts added or removed).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..scene import Scene

#: Effect kinds, cheapest first; an edit's kind is the dearest of what it changes.
EFFECT_KINDS = ("none", "flux", "emitter", "material", "geometry", "topology")


@dataclass(frozen=True)
class Effect:
    """The photometric effect of an edit, with what it touches (prim paths)."""

    kind: str = "none"
    emitters: tuple[str, ...] = ()
    materials: tuple[str, ...] = ()
    parts: tuple[str, ...] = ()
    prims: tuple[str, ...] = field(default=(), compare=False)  # USD's changed paths

    def as_dict(self) -> dict:
        return {"kind": self.kind, "emitters": list(self.emitters),
                "materials": list(self.materials), "parts": list(self.parts),
                "prims": list(self.prims)}


def _dearest(kinds) -> str:
    return max(kinds, key=EFFECT_KINDS.index, default="none")


def _same_emitter(a, b, but: tuple[str, ...] = ()) -> bool:
    """Field-by-field equality of two emitters (their transforms are arrays)."""
    return all(np.array_equal(getattr(a, f.name), getattr(b, f.name))
               for f in dataclasses.fields(a) if f.name not in but)


def _parts_geometry(scene: Scene) -> dict[str, tuple[bytes, bytes]]:
    """Per part: its triangles' bytes and material indices' bytes."""
    out = {}
    for i, name in enumerate(scene.parts):
        sel = scene.part_index == i
        out[name] = (np.ascontiguousarray(scene.triangles[sel]).tobytes(),
                     np.ascontiguousarray(scene.material_index[sel]).tobytes())
    return out


def classify(old: Scene, new: Scene, prims=()) -> Effect:
    """The effect of going from ``old`` to ``new`` (``prims``: what USD said changed)."""
    kinds, emitters, materials, parts = [], [], [], []
    if (old.up_axis, old.meters_per_unit, old.luminaire_path) != \
            (new.up_axis, new.meters_per_unit, new.luminaire_path):
        kinds.append("topology")
    old_e = {e.path: e for e in old.emitters}
    new_e = {e.path: e for e in new.emitters}
    if list(old_e) != list(new_e):
        kinds.append("topology")
        emitters += sorted(set(old_e) ^ set(new_e))
    for path in set(old_e) & set(new_e):
        a, b = old_e[path], new_e[path]
        if _same_emitter(a, b):
            continue
        emitters.append(path)
        kinds.append("flux" if _same_emitter(a, b, but=("flux",)) else "emitter")
    old_m = {m.path: m for m in old.materials}
    new_m = {m.path: m for m in new.materials}
    materials += sorted(p for p in set(old_m) | set(new_m) if old_m.get(p) != new_m.get(p))
    if materials:
        kinds.append("material")
    old_g, new_g = _parts_geometry(old), _parts_geometry(new)
    if set(old_g) != set(new_g):
        kinds.append("topology")
        parts += sorted(set(old_g) ^ set(new_g))
    changed = sorted(p for p in set(old_g) & set(new_g) if old_g[p] != new_g[p])
    if changed:
        parts += changed
        # the same triangles with other material slots are a material change
        moved = any(old_g[p][0] != new_g[p][0] for p in changed)
        kinds.append("geometry" if moved else "material")
    return Effect(_dearest(kinds), tuple(sorted(emitters)), tuple(materials),
                  tuple(sorted(parts)), tuple(sorted(map(str, prims))))
