"""Stages traced once per test session, with their photometry and the LDT lumitrace writes
for them (what third-party readers are given)."""
from __future__ import annotations

import atexit
import functools
import shutil
import tempfile
from pathlib import Path

from lumitrace.photometry.distribution import photometry_of
from lumitrace.publish.photometric import photometric_paths, write_photometric_files
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage

from .paths import ROOT

_FOLDER = Path(tempfile.mkdtemp(prefix="lumitrace-traced-"))
atexit.register(shutil.rmtree, _FOLDER, True)

#: The stages the photometry cross-checks use, by short name.
STAGES = {"demo": "stages/downlight.usda", "louvre": "stages/louvre.usda",
          "disc": "stages/reference/lambertian_disc.usda",
          "isotropic": "stages/reference/isotropic.usda"}


@functools.lru_cache(maxsize=None)
def traced(name: str, photons: int = 400_000, seed: int = 1):
    """(scene, result, photometry, LDT path) of stage ``name`` traced with ``photons``."""
    scene = read_stage(ROOT / STAGES[name])
    result = run(scene, TraceSettings(photons=photons, resolution=16, seed=seed, threads=2))
    ph = photometry_of(scene, result.accumulator)
    out = _FOLDER / f"{name}-{photons}-{seed}"
    out.mkdir()
    paths = photometric_paths(out, name)
    write_photometric_files(scene, ph, paths, name, pictures=False)
    return scene, result, ph, paths["ldt"]
