"""A scene delta to a mesh's profile, sent to a real ``lumitrace serve``: the service
writes the mesh's new points and faces into its edits layer with the profile (so a DCC
that loads the layer sees the geometry traced) and classifies the edit as geometry; a bad
profile is refused (422) naming what is wrong."""
from __future__ import annotations

import numpy as np
from pxr import Usd
from service_process import Service

from helpers.fit_stages import PROFILE_POINTS, profile_reflector

from lumitrace.client import ServiceError
from lumitrace.filenames import edits_layer_path
from lumitrace.stage.profile import profile_mesh, read_profile


def test_a_profile_delta_rewrites_the_mesh_in_the_edits_layer(tmp_path):
    stage = profile_reflector(tmp_path / "p.usda")
    new = [[r + 0.002, z] for r, z in PROFILE_POINTS]
    with Service(stage, "--photons", 20000, "--resolution", 8, "--threads", 1,
                 "--no-viewer", "--quiet", "--no-sublayer") as s:
        s.wait_done(0, pictures=False)
        answer = s.client.set("/Luminaire/Reflector", "lumitrace:profile:points", new)
        assert answer["effect"]["kind"] == "geometry"
        assert answer["effect"]["parts"] == ["/Luminaire/Reflector"]
        try:
            s.client.set("/Luminaire/Reflector", "lumitrace:profile:points",
                         [[0.01, 0.0], [-0.01, -0.01]])
            raise AssertionError("a negative radius was accepted")
        except ServiceError as refused:
            assert refused.status == 422
            assert "negative radius" in refused.problems[0]["why"]
    layer = edits_layer_path(stage)
    composed = Usd.Stage.Open(str(stage))
    composed.GetSessionLayer().subLayerPaths.append(str(layer))
    prim = composed.GetPrimAtPath("/Luminaire/Reflector")
    want, counts, indices = profile_mesh(read_profile(prim, Usd.TimeCode.Default(), "Z"))
    np.testing.assert_allclose(np.array(prim.GetAttribute("points").Get()), want, atol=1e-7)
    assert list(prim.GetAttribute("faceVertexCounts").Get()) == counts.tolist()
    np.testing.assert_allclose(np.array(prim.GetAttribute("lumitrace:profile:points").Get()),
                               new, atol=1e-7)
