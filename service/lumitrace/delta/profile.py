"""Writing a mesh from its profile: where lumitrace changes a mesh's
``lumitrace:profile:*`` (a scene delta, a fit candidate, the fit's edits layer), the mesh's
points, faces and extent are authored anew in the same layer, so every DCC that composes
it sees the geometry that is traced (see :mod:`lumitrace.stage.profile`)."""
from __future__ import annotations

import numpy as np
from pxr import Gf, Usd, UsdGeom, Vt

from ..stage.profile import Profile, profile_mesh, read_profile


def write_profile_mesh(prim: Usd.Prim, profile: Profile | None = None) -> Profile:
    """Author ``prim``'s points, faceVertexCounts, faceVertexIndices and extent from its
    profile (``profile``, or the one it composes now, checked: a
    :class:`~lumitrace.errors.StageError` names a bad value) in the stage's current edit
    target; returns the profile."""
    if profile is None:
        up = str(UsdGeom.GetStageUpAxis(prim.GetStage()))
        profile = read_profile(prim, Usd.TimeCode.Default(), up)
    points, counts, indices = profile_mesh(profile)
    mesh = UsdGeom.Mesh(prim)
    mesh.CreatePointsAttr().Set(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr().Set(Vt.IntArray.FromNumpy(counts))
    mesh.CreateFaceVertexIndicesAttr().Set(Vt.IntArray.FromNumpy(indices))
    lo, hi = points.min(axis=0), points.max(axis=0)
    mesh.CreateExtentAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)),
                                               Gf.Vec3f(*map(float, hi))]))
    return profile
