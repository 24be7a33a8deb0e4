"""The editor's view of each part's local transform, read from the prim's xformOps: the
translate (stage units), rotate (XYZ Euler, degrees) and scale a ``transform`` delta
composes (:func:`~lumitrace.delta.apply.transform_matrix`) that give the same local matrix,
and that matrix; or why the editor's fields cannot show it (a shear, an animated or
parent-resetting transform, a prim with none), in which case the part's transform is
shown read-only and kept as it is."""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from pxr import Gf, Usd, UsdGeom

from ..delta.apply import transform_matrix

#: Largest departure (relative to the matrix's largest entry) of the recomposed transform
#: from the stage's for the fields to show it.
TOLERANCE = 1e-9


def part_transforms(stage: Usd.Stage, paths, time: float | None = None
                    ) -> dict[str, dict[str, Any]]:
    """Per part path, :func:`local_transform` of its prim at ``time`` (None: default)."""
    code = Usd.TimeCode.Default() if time is None else Usd.TimeCode(time)
    return {path: local_transform(stage, path, code) for path in paths}


def local_transform(stage: Usd.Stage, path: str, time: Usd.TimeCode) -> dict[str, Any]:
    """``{"editable": True, "translate", "rotate", "scale", "matrix", "ops"}`` of the prim
    at ``path``, or ``{"editable": False, "note", ...}`` saying why the fields cannot show
    (or a delta could not keep) its transform."""
    def fixed(note: str, matrix=None) -> dict[str, Any]:
        return {"editable": False, "note": note, "matrix": matrix}

    if "[" in path:
        return fixed("one of a point instancer's instances: edit the instancer")
    prim = stage.GetPrimAtPath(path)
    if not prim:
        return fixed("no prim at this path")
    if prim.IsInstanceProxy():
        return fixed("part of an instance: edit its prototype or the instance prim")
    xf = UsdGeom.Xformable(prim)
    if not xf:
        return fixed(f"a {prim.GetTypeName() or 'typeless'} prim has no transform")
    m = xf.GetLocalTransformation(time)
    rows = [[float(x) for x in m.GetRow(i)] for i in range(4)]
    ops = [op.GetOpName() for op in xf.GetOrderedXformOps()]
    if xf.GetResetXformStack():
        return fixed("resets its parents' transforms (!resetXformStack!): kept as it is",
                     rows)
    if xf.TransformMightBeTimeVarying():
        return fixed("its transform is animated: kept as it is", rows)
    trs = _common_vectors(prim, time) or decompose(m)
    if trs is None:
        return fixed(f"its transform ({', '.join(ops) or 'none'}) is not a translate, "
                     "rotate and scale (a shear or a projection): kept as it is", rows)
    translate, rotate, scale = trs
    return {"editable": True, "note": None, "translate": translate, "rotate": rotate,
            "scale": scale, "matrix": rows, "ops": ops}


def _common_vectors(prim: Usd.Prim, time: Usd.TimeCode
                    ) -> tuple[list[float], list[float], list[float]] | None:
    """The values of translate, rotateXYZ and scale ops as authored (no pivot), where the
    prim's ops are those (XformCommonAPI's stack, rotation order XYZ); else None."""
    api = UsdGeom.XformCommonAPI(prim)
    if not api:
        return None
    t, r, s, pivot, order = api.GetXformVectors(time)
    if order != UsdGeom.XformCommonAPI.RotationOrderXYZ or any(pivot):
        return None
    return ([_clean(float(x)) for x in t], [_clean(float(x)) for x in r],
            [_clean(float(x)) for x in s])


def decompose(m: Gf.Matrix4d) -> tuple[list[float], list[float], list[float]] | None:
    """(translate, rotate XYZ in degrees, scale) whose ``transform`` delta gives ``m``
    (USD's row vectors: scale, then rotate about X, Y, Z, then translate), or None where
    none does (a shear, a projection)."""
    a = np.array([[m[i][j] for j in range(4)] for i in range(4)], dtype=np.float64)
    if not np.all(np.isfinite(a)) or np.any(np.abs(a[:3, 3]) > 0) or a[3, 3] != 1.0:
        return None
    linear, t = a[:3, :3], a[3, :3]
    s = np.linalg.norm(linear, axis=1)
    if np.any(s <= 0):
        return None
    if np.linalg.det(linear) < 0:
        s = -s  # a mirror: every axis flipped (R keeps det +1)
    r = linear / s[:, None]  # rows of the rotation (row vectors: p' = p S R + t)
    # R = X(a) Y(b) Z(g) for row vectors is (Cz(g) Cy(b) Cx(a))^T in column terms
    c = r.T
    if abs(c[2, 0]) < 1.0 - 1e-12:
        b = -math.asin(max(-1.0, min(1.0, c[2, 0])))
        x = math.atan2(c[2, 1], c[2, 2])
        z = math.atan2(c[1, 0], c[0, 0])
    else:  # gimbal lock: Y at +-90 deg, Z taken as 0
        b = -math.copysign(math.pi / 2, c[2, 0])
        x = math.atan2(-c[1, 2], c[1, 1])
        z = 0.0
    rotate = [_clean(math.degrees(v)) for v in (x, b, z)]
    translate = [_clean(float(v)) for v in t]
    scale = [_clean(float(v)) for v in s]
    back = transform_matrix({"translate": translate, "rotate": rotate, "scale": scale})
    b_ = np.array([[back[i][j] for j in range(4)] for i in range(4)])
    if np.max(np.abs(b_ - a)) > TOLERANCE * max(1.0, float(np.max(np.abs(a)))):
        return None
    return translate, rotate, scale


def _clean(v: float) -> float:
    """``v`` with a rounding residue (below 1e-12 of 1) made 0, and -0 made 0."""
    return 0.0 if abs(v) < 1e-12 else v
