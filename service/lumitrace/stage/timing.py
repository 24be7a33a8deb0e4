"""The one time code every value of a stage is read at.

A caller's ``time`` is used as given. Otherwise a static luminaire (no attribute of the
luminaire prim, its descendants or its ancestors has a time sample) is read at
``Usd.TimeCode.Default()``, exactly as authored. An animated one is read at the stage's
``startTimeCode`` when that is authored, else at the earliest time sample of its animated
attributes, with a warning: read at Default, an attribute with only time samples would
give its fallback (a light's intensity of 1, a mesh without points, an identity
transform) instead of anything authored.
"""
from __future__ import annotations

import math
from typing import Callable

from pxr import Usd

#: Prims whose attributes are looked at: as the reader walks them, and the "over" and
#: "class" prims a point instancer's prototypes may hide under.
_PREDICATE = Usd.TraverseInstanceProxies(Usd.PrimIsActive & Usd.PrimIsLoaded)


def requested_time(time) -> Usd.TimeCode | None:
    """A caller's ``time`` argument as a time code; None when not given."""
    if time is None:
        return None
    if isinstance(time, Usd.TimeCode):
        return time
    return Usd.TimeCode(float(time))


def scene_time_code(time: Usd.TimeCode) -> float | None:
    """The time code as :attr:`Scene.time_code` records it: None for the default time."""
    return None if time.IsDefault() else float(time.GetValue())


def read_time(stage: Usd.Stage, root: Usd.Prim, time: Usd.TimeCode | None,
              warn: Callable[[str], None]) -> Usd.TimeCode:
    """The time code to read the luminaire ``root`` at (see the module's docstring)."""
    if time is not None:
        return time
    animated = animated_attributes(root)
    if not animated:
        return Usd.TimeCode.Default()
    if stage.HasAuthoredMetadata("startTimeCode"):
        value, why = float(stage.GetStartTimeCode()), "the stage's startTimeCode"
    else:
        firsts = [samples[0] for samples in (a.GetTimeSamples() for a in animated) if samples]
        if firsts:
            value, why = float(min(firsts)), "its earliest time sample"
        else:  # time-varying without samples (a spline): the stage's start, 0 by default
            value, why = float(stage.GetStartTimeCode()), "the stage's start time"
    if not math.isfinite(value):
        value, why = 0.0, f"{why} is not finite"
    example = animated[0]
    count = len(animated)
    warn(f"{root.GetPath()}: {count} attribute{'s are' if count != 1 else ' is'} animated "
         f"(e.g. {example.GetPrim().GetPath()}.{example.GetName()}): the luminaire is read "
         f"at time code {value:g} ({why})")
    return Usd.TimeCode(value)


def animated_attributes(root: Usd.Prim) -> list[Usd.Attribute]:
    """The attributes of ``root``, its descendants and its ancestors that have time
    samples (or may vary over time otherwise, as a spline or value clips do)."""
    prims = list(Usd.PrimRange(root, _PREDICATE))
    parent = root.GetParent()
    while parent and not parent.IsPseudoRoot():
        prims.append(parent)
        parent = parent.GetParent()
    return [attr for prim in prims for attr in prim.GetAttributes()
            if attr.GetNumTimeSamples() > 0 or attr.ValueMightBeTimeVarying()]
