"""Many identical lights as one emitter: an LED board of thousands of lights that differ only
in place and flux is traced as one flux-weighted mixture (each photon from one light, drawn
by its share of the flux), so the work per round, per tally and per measurement follows the
photons, not the number of lights.

The mixture is the same light distribution as the lights traced one by one, and its counts
are one emitter's: binomial in its photons, so their variance is exact. What a group gives
up is per-light bookkeeping: a flux edit that keeps the lights' shares (dimming the board)
is still a rescale, one that changes a single light's share retraces the group.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .model import Emitter, LightGroup

#: Identical lights are grouped from this many on: below it, per-light work is small and
#: each light keeps its own tallies (and its own flux rescale).
GROUP_MIN = 64


def _signature(e: Emitter):
    """What lights of a group share: everything but their place and flux (and path). Lights
    with files, meshes or spectra per ray are never grouped."""
    if e.rays is not None or e.triangles is not None or e.group is not None or e.flux <= 0:
        return None
    m = np.asarray(e.to_world, np.float64)
    return (e.kind, e.radius, e.width, e.height, e.length, e.treat_as_point, e.cone_angle,
            e.cone_softness, e.focus, e.ies, e.two_sided, tuple(e.spectrum),
            m[:3, :3].tobytes(), m[3].tobytes())


def group_emitters(emitters, min_size: int = GROUP_MIN) -> tuple[Emitter, ...]:
    """``emitters`` with every set of at least ``min_size`` identical lights (same kind,
    sizes, shaping, spectrum and linear transform) replaced by one emitter that stands for
    them all, at the place of the set's first light; the others as they are, in order."""
    emitters = tuple(emitters)
    sets: dict = {}
    for i, e in enumerate(emitters):
        key = _signature(e)
        if key is not None:
            sets.setdefault(key, []).append(i)
    grouped = {members[0]: members for members in sets.values() if len(members) >= min_size}
    if not grouped:
        return emitters
    taken = {i for members in grouped.values() for i in members}
    out = []
    for i, e in enumerate(emitters):
        if i in grouped:
            out.append(_group([emitters[k] for k in grouped[i]]))
        elif i not in taken:
            out.append(e)
    return tuple(out)


def _group(lights: list[Emitter]) -> Emitter:
    """One emitter for ``lights`` (identical but for place and flux): the first light's
    shape and transform, the lights' offsets from it and their shares of the flux."""
    first = lights[0]
    origins = np.array([np.asarray(e.to_world, np.float64)[:3, 3] for e in lights])
    flux = np.array([e.flux for e in lights], np.float64)
    total = float(flux.sum())
    group = LightGroup(tuple(e.path for e in lights), origins - origins[0], flux / total)
    return dataclasses.replace(first, path=f"{first.path}[+{len(lights) - 1}]", flux=total,
                               group=group)
