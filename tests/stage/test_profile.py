"""A mesh's generating profile (``LumitraceProfileAPI``): the mesh made from it has the
areas and extents of the surface of revolution (or extrusion) it stands for, the stage
reader validates the profile and says when the points no longer follow it, and a scene
delta to the profile rewrites the mesh's points in the edits layer."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

from lumitrace import schema
from lumitrace.delta.apply import apply_deltas
from lumitrace.delta.profile import write_profile_mesh
from lumitrace.delta.protocol import DeltaError
from lumitrace.errors import StageError
from lumitrace.stage.profile import check_profile, profile_mesh, read_profile
from lumitrace.stage.reader import read_stage, scene_from_stage

from helpers.fit_stages import PROFILE_POINTS, profile_reflector


def _area(points, counts, indices) -> float:
    """Area of a mesh of planar quads and triangles."""
    total, k = 0.0, 0
    for c in counts:
        p = points[indices[k:k + c]]
        for i in range(1, c - 1):
            total += 0.5 * np.linalg.norm(np.cross(p[i] - p[0], p[i + 1] - p[0]))
        k += c
    return total


def test_a_revolved_profile_is_the_surface_of_revolution_of_its_polyline():
    """A cone frustum's band: the mesh's area tends to the frustum's lateral area pi (r1 +
    r2) s as the segments grow (an inscribed polygon: cos(pi / n) short), its extent is the
    profile's, and a point on the axis makes triangles, not degenerate quads."""
    p = check_profile([(0.0, 0.0), (0.01, -0.02), (0.03, -0.03)], "revolve", 256, 1.0, "/M")
    pts, counts, idx = profile_mesh(p)
    s1, s2 = math.hypot(0.01, 0.02), math.hypot(0.02, 0.01)
    lateral = math.pi * (0.01 * s1 + (0.01 + 0.03) * s2)
    assert _area(pts, counts, idx) == pytest.approx(lateral, rel=2e-4)
    assert counts.tolist() == [3] * 256 + [4] * 256
    np.testing.assert_allclose(pts.min(axis=0), [-0.03, -0.03, -0.03], atol=1e-12)
    np.testing.assert_allclose(pts.max(axis=0), [0.03, 0.03, 0.0], atol=1e-12)
    # the revolve turns about the stage's up axis: Y in a Y-up stage
    y = profile_mesh(check_profile(p.points, "revolve", 256, 1.0, "/M", up_axis="Y"))[0]
    np.testing.assert_allclose(y[:, 1], np.repeat(pts[:, 2], 1), atol=0)


def test_an_extruded_profile_is_its_polyline_swept_along_its_length():
    p = check_profile([(-0.02, 0.0), (0.0, -0.01), (0.02, 0.0)], "extrude", 4, 0.5, "/M")
    pts, counts, idx = profile_mesh(p)
    assert _area(pts, counts, idx) == pytest.approx(2 * math.hypot(0.02, 0.01) * 0.5)
    assert np.ptp(pts[:, 1]) == pytest.approx(0.5) and len(counts) == 2 * 4


@pytest.mark.parametrize("points, kind, segments, length, words", [
    ([(0.01, 0.0)], "revolve", 64, 1.0, "at least 2"),
    ([(0.01, 0.0), (float("nan"), 1.0)], "revolve", 64, 1.0, "point 1 is NaN"),
    ([(0.01, 0.0), (-0.01, -0.01)], "revolve", 64, 1.0, "negative radius"),
    ([(0.01, 0.0), (0.01, 0.0)], "revolve", 64, 1.0, "are the same"),
    ([(0.01, 0.0), (0.02, -0.01)], "spin", 64, 1.0, "unknown token 'spin'"),
    ([(0.01, 0.0), (0.02, -0.01)], "revolve", 2, 1.0, "between 3 and 4096"),
    ([(0.01, 0.0), (0.02, -0.01)], "extrude", 4, 0.0, "length must be finite and > 0"),
])
def test_bad_profiles_are_one_error_naming_the_property(points, kind, segments, length, words):
    with pytest.raises(StageError) as err:
        check_profile(points, kind, segments, length, "/Luminaire/Reflector")
    assert words in str(err.value) and "/Luminaire/Reflector.lumitrace:profile:" in \
        str(err.value)


def test_the_reader_validates_the_profile_and_warns_when_points_left_it(tmp_path):
    path = profile_reflector(tmp_path / "p.usda")
    scene = read_stage(path)
    assert not [w for w in scene.warnings if "profile" in w]
    stage = Usd.Stage.Open(str(path))
    prim = stage.GetPrimAtPath("/Luminaire/Reflector")
    pts = np.array(prim.GetAttribute("points").Get())
    pts[0, 2] += 0.001  # a DCC moved a vertex by hand
    prim.GetAttribute("points").Set(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)))
    warned = scene_from_stage(stage).warnings
    assert any("not those of its profile" in w and "/Luminaire/Reflector" in w
               for w in warned)
    prim.GetAttribute(schema.PROFILE_SEGMENTS).Set(1)
    with pytest.raises(StageError, match="lumitrace:profile:segments: must be between 3"):
        scene_from_stage(stage)


def test_a_delta_to_the_profile_rewrites_the_mesh_in_the_edits_layer(tmp_path):
    path = profile_reflector(tmp_path / "p.usda")
    before = path.read_bytes()
    stage = Usd.Stage.Open(str(path))
    edits = Sdf.Layer.CreateAnonymous()
    stage.GetSessionLayer().subLayerPaths.append(edits.identifier)
    new = [[r + 0.002, z] for r, z in PROFILE_POINTS]
    apply_deltas(stage, edits, [{"op": "set", "path": "/Luminaire/Reflector",
                                 "property": "lumitrace:profile:points", "value": new}], ".")
    prim = stage.GetPrimAtPath("/Luminaire/Reflector")
    want = profile_mesh(read_profile(prim, Usd.TimeCode.Default(), "Z"))[0]
    np.testing.assert_allclose(np.array(prim.GetAttribute("points").Get()), want, atol=1e-7)
    spec = edits.GetPrimAtPath("/Luminaire/Reflector")
    assert "points" in spec.attributes and "faceVertexIndices" in spec.attributes
    assert path.read_bytes() == before  # the stage's own file is never written
    # the traced scene is the new surface: its radii are the profile's
    tri = scene_from_stage(stage).triangles
    r = np.hypot(tri[..., 0], tri[..., 1])
    assert r.max() == pytest.approx(max(p[0] for p in new), rel=1e-6)
    # a bad profile is the delta's problem, naming it, and the layer is left as it was
    text = edits.ExportToString()
    with pytest.raises(DeltaError) as err:
        apply_deltas(stage, edits, [{"op": "set", "path": "/Luminaire/Reflector",
                                     "property": "lumitrace:profile:points",
                                     "value": [[0.01, 0.0], [-0.01, -0.01]]}], ".")
    assert "lumitrace:profile:points" in str(err.value) and "negative radius" in \
        str(err.value)
    assert edits.ExportToString() == text
    with pytest.raises(DeltaError, match="must be one of revolve, extrude"):
        apply_deltas(stage, edits, [{"op": "set", "path": "/Luminaire/Reflector",
                                     "property": "lumitrace:profile:kind",
                                     "value": "spin"}], ".")


def test_write_profile_mesh_authors_what_the_profile_makes():
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, "Z")
    prim = UsdGeom.Mesh.Define(stage, "/M").GetPrim()
    prim.ApplyAPI(schema.PROFILE_API)
    prim.GetAttribute(schema.PROFILE_POINTS).Set(
        Vt.Vec2fArray([Gf.Vec2f(0.0, 0.0), Gf.Vec2f(1.0, -1.0)]))
    profile = write_profile_mesh(prim)
    assert profile.segments == schema.PROFILE_FALLBACKS[schema.PROFILE_SEGMENTS]
    ext = np.array(prim.GetAttribute("extent").Get())
    np.testing.assert_allclose(ext, [[-1, -1, -1], [1, 1, 0]], atol=1e-6)
