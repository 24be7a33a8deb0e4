"""Where prims are placed: world transforms, PointInstancer prototype frames, and the
error that names the xformOp of a transform that cannot be used."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NoReturn

import numpy as np
from pxr import Tf, Usd, UsdGeom

from ..errors import StageError
from .diagnostics import tf_message


@dataclass
class Frame:
    """Where gprims found by a walk are placed.

    ``anchor`` None: at their own world transform. Otherwise they belong to a PointInstancer
    prototype rooted at ``anchor`` and are placed once per base: a row-vector matrix from the
    prototype root's space to the world (stage units) and a label for emitter paths.
    """

    anchor: Usd.Prim | None = None
    bases: list[tuple[np.ndarray, str]] = field(default_factory=list)


def placements(xf: UsdGeom.XformCache, prim: Usd.Prim, frame: Frame
               ) -> list[tuple[np.ndarray, str]]:
    """Row-vector local-to-world matrices (stage units) of ``prim``, one per placement."""
    time = xf.GetTime()
    try:
        if frame.anchor is None:
            local = np.array(xf.GetLocalToWorldTransform(prim))
            if not np.isfinite(local).all():
                raise_bad_transform(prim, time)
            return [(local, "")]
        relative, _ = xf.ComputeRelativeTransform(prim, frame.anchor)
    except Tf.ErrorException as exc:  # e.g. an op whose value has the wrong type
        raise_bad_transform(prim, time, exc)
    relative = np.array(relative)
    if not np.isfinite(relative).all():
        raise_bad_transform(prim, time)
    return [(relative @ base, label) for base, label in frame.bases]


def raise_bad_transform(prim: Usd.Prim, time: Usd.TimeCode, exc: Exception | None = None,
                        singular: bool = False) -> NoReturn:
    """Name the prim and xformOp whose transform cannot be evaluated, is NaN or
    infinite, or (``singular``) collapses space (a zero scale)."""
    what = ("transform collapses a light to nothing (a scale of 0): it has no emitting "
            "surface or direction" if singular else "transform is NaN or infinite")
    p = prim
    while p and not p.IsPseudoRoot():
        xformable = UsdGeom.Xformable(p)
        if xformable:
            for op in xformable.GetOrderedXformOps():
                try:
                    m = np.array(op.GetOpTransform(time))
                except Tf.ErrorException as op_exc:
                    raise StageError(f"transform op cannot be evaluated: "
                                     f"{tf_message(op_exc)}", str(p.GetPath()),
                                     op.GetName()) from op_exc
                if not np.isfinite(m).all() or (singular and not invertible(m[:3, :3])):
                    raise StageError(what, str(p.GetPath()), op.GetName())
        p = p.GetParent()
    if exc is not None:
        raise StageError(f"transform cannot be evaluated: {tf_message(exc)}",
                         str(prim.GetPath()), "xformOpOrder") from exc
    raise StageError("world " + what, str(prim.GetPath()), "xformOpOrder")


def invertible(linear: np.ndarray) -> bool:
    """Whether a 3x3 map is far from singular (condition number below 1e12)."""
    sv = np.linalg.svd(np.asarray(linear, dtype=np.float64), compute_uv=False)
    return bool(sv[0] > 0.0 and sv[-1] > 1e-12 * sv[0])
