"""The lat-long texture reads back, through OpenImageIO's own TextureSystem, as the
intensity of the direction looked up (in the frame of a DomeLight with poleAxis scene)."""
from __future__ import annotations

import shutil

import numpy as np
import OpenImageIO as oiio
import pytest

from lumitrace.film.cubemap import sample_map
from lumitrace.publish.latlong import stage_to_dome
from lumitrace.publish.outputs import write_outputs
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage
from helpers.paths import STAGES


@pytest.fixture(scope="module")
def downlight(tmp_path_factory):
    folder = tmp_path_factory.mktemp("latlong")
    stage = folder / "downlight.usda"
    shutil.copy(STAGES / "downlight.usda", stage)
    scene = read_stage(stage)
    result = run(scene, TraceSettings(photons=400_000, seed=1, resolution=32))
    return scene, result, write_outputs(result, None, pictures=False)


def test_oiio_environment_lookups_return_the_intensity(downlight):
    scene, result, record = downlight
    path = record["latlong_map"]
    spec = oiio.ImageInput.open(path).spec()
    assert spec.tile_width == 64 and spec.width == 2 * spec.height
    assert oiio.ImageInput.open(path).spec(0, 1).width == spec.width // 2  # mip-mapped
    ts = oiio.TextureSystem()
    opt = oiio.TextureOpt()
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(40, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dirs = np.vstack([dirs, [[0.0, 0.0, -1.0], [0.3, 0.1, -0.95]]])  # nadir: the peak
    want = sample_map(result.estimate.filtered, dirs)
    got = np.array([ts.environment(str(path), opt, tuple(map(float, d)), (0.0, 0.0, 0.0),
                                   (0.0, 0.0, 0.0), 3)[0]
                    for d in stage_to_dome(dirs, scene.up_axis)])
    # two bilinear resamplings (cube to lat-long, then the lookup) apart, where the map is
    # smooth; a wrong frame would be off by far more (the beam points at nadir only)
    diff = np.abs(got - want) / want.max()
    assert np.median(diff) < 0.005 and diff.max() < 0.03, (np.median(diff), diff.max())
    assert got[-2] == pytest.approx(want[-2], rel=0.02)
    peak = ts.environment(str(path), opt, (0.0, -1.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1)
    assert peak[0] > 0.8 * result.estimate.filtered.max()


def test_relative_error_is_finite_and_capped(downlight):
    from lumitrace.publish.exr import read_intensity_exr
    from lumitrace.publish.outputs import MAX_TEXEL_ERROR

    _, _, record = downlight
    channels = read_intensity_exr(record["intensity_map"])[0]
    rel = channels["relativeError"]
    assert np.isfinite(rel).all() and rel.max() <= MAX_TEXEL_ERROR
