"""The luminaire's own exit rays as a TM-25 ray file: read back bit for bit, holding the
luminaire's escaping flux, and a light emitting them gives the luminaire's far field within
the noise of both traces."""
import shutil

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdLux

from helpers.paths import ROOT
from lumitrace import tm25
from lumitrace.errors import LumitraceError
from lumitrace.photometry.measured import measure
from lumitrace.publish.rays import check_ray_count, write_ray_file
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage
from lumitrace.trace.exit_rays import exit_rays

GAMMAS = np.arange(0.0, 180.0 + 1e-9, 5.0)


def _ray_light_stage(folder, ray_file):
    path = folder / "stand_in.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.001)
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(root.GetPrim())
    light = UsdLux.SphereLight.Define(stage, "/Luminaire/Rays")
    p = light.GetPrim()
    p.AddAppliedSchema("LumitraceEmitterAPI")
    p.CreateAttribute("lumitrace:rayFile", Sdf.ValueTypeNames.Asset).Set(
        Sdf.AssetPath("./" + ray_file.name))
    stage.Save()
    return path


def test_a_luminaire_traced_from_its_own_exit_rays_gives_its_far_field(tmp_path):
    stage = tmp_path / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage)
    scene = read_stage(stage)
    made = 600_000
    ray_file = tmp_path / "downlight.TM25RAY"
    rays = exit_rays(scene, made, seed=1)
    write_ray_file(ray_file, rays, scene)
    back = tm25.read_tm25(ray_file)
    for name in ("positions", "directions", "flux"):
        assert np.array_equal(getattr(back, name), getattr(rays, name))
    # the rays are the escapes of those photons: the same count and flux as a trace of them
    direct = run(scene, TraceSettings(photons=made, resolution=8, seed=1))
    esc = direct.accumulator.fluxes()["escaped"]
    assert len(back) == sum(t.escaped for t in direct.accumulator.emitters)
    assert back.luminous_flux == pytest.approx(esc, rel=1e-5)
    # every ray starts on the luminaire's bounding box, in the luminaire's frame (mm)
    lo, hi = (np.array(v) * 1000 for v in (direct.accumulator.goniometer.lo,
                                           direct.accumulator.goniometer.hi))
    on_box = np.min(np.abs(np.concatenate([back.positions - lo, back.positions - hi], 1)), 1)
    assert on_box.max() < 1e-3

    alone = read_stage(_ray_light_stage(tmp_path, ray_file))
    assert alone.emitters[0].flux == pytest.approx(esc, rel=1e-5)
    n = 300_000
    a = measure(run(scene, TraceSettings(photons=n, resolution=8, seed=2)).accumulator,
                GAMMAS, 15.0).full()
    b = measure(run(alone, TraceSettings(photons=n, resolution=8, seed=3)).accumulator,
                GAMMAS, 15.0).full()
    # the stand-in emits the escaped flux: the same candela; its errors count the ray set's
    # own noise (its photons are drawn from a finite set of rays)
    sb = b.sigma * np.sqrt(1.0 + n / len(back))
    s = np.sqrt(a.sigma**2 + sb**2)
    live = s > 0
    z = (a.candela - b.candela)[live] / s[live]
    assert np.abs(z).max() < 5.0 and abs(np.mean(z)) < 0.25 and np.var(z) < 1.6, \
        (np.abs(z).max(), np.mean(z), np.var(z))


def test_a_ray_file_above_its_cap_is_refused(tmp_path):
    stage = tmp_path / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage)
    with pytest.raises(LumitraceError) as info:
        check_ray_count(tmp_path / "big.TM25RAY", 2000, max_rays=1000)
    assert "1000 rays" in str(info.value)
    assert not (tmp_path / "big.TM25RAY").exists()


def test_the_rays_command_writes_the_file_beside_the_stage(tmp_path):
    import subprocess
    import sys

    stage = tmp_path / "downlight.usda"
    shutil.copy(ROOT / "stages" / "downlight.usda", stage)
    out = subprocess.run([sys.executable, "-m", "lumitrace.cli", "rays", str(stage),
                          "--photons", "20000"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    f = tm25.read_tm25(tmp_path / "downlight.TM25RAY")
    assert f"{len(f):,} rays" in out.stdout and 0 < len(f) < 20000
    bad = subprocess.run([sys.executable, "-m", "lumitrace.cli", "rays", str(stage),
                          "--photons", "20000", "--max-rays", "100"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "100 rays" in bad.stderr
