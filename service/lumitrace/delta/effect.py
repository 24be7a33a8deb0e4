"""What an edit changes, photometrically: the old and the new scene compared.

The kinds, from the cheapest to the dearest to follow: ``none`` (nothing the tracer sees:
names, display colour, prims outside the luminaire, untraced purposes), ``flux`` (emitter
fluxes, or lights' colours where no surface has one: a rescale of their counts, nothing
traced), ``emitter`` (an emitter's shape,
shaping or placement), ``material``, ``geometry`` (a part's transform or points) and
``topology`` (emitters or parts added or removed).
"""
from __future__ import annotations

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
        if a.same_as(b):
            continue
        emitters.append(path)
        # where no surface has a colour, a light's colour is a rescale of X and Z too
        rescaled = ("flux", "spectrum") if new.colour != "spectral" else ("flux",)
        kinds.append("flux" if a.same_as(b, ignore=rescaled) else "emitter")
    old_m = {m.path: m for m in old.materials}
    new_m = {m.path: m for m in new.materials}
    materials += sorted(p for p in set(old_m) | set(new_m) if old_m.get(p) != new_m.get(p))
    if materials:
        kinds.append("material")
    old_g, new_g = old.part_geometry(), new.part_geometry()
    if set(old_g) != set(new_g):
        kinds.append("topology")
        parts += sorted(set(old_g) ^ set(new_g))
    moved = sorted(p for p in set(old_g) & set(new_g)
                   if not np.array_equal(old_g[p][0], new_g[p][0]))
    # the same triangles with other materials in their slots are a material change
    slots = sorted(p for p in set(old_g) & set(new_g) if p not in moved
                   and not np.array_equal(old_g[p][1], new_g[p][1]))
    if moved or slots:
        parts += sorted(moved + slots)
        kinds.append("geometry" if moved else "material")
    return Effect(_dearest(kinds), tuple(sorted(emitters)), tuple(materials),
                  tuple(sorted(parts)), tuple(sorted(map(str, prims))))
