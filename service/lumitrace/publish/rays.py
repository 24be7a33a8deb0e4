"""The luminaire as a near-field source: its own exit rays as an IES TM-25 ray file.

Photons are traced through the luminaire as for its map (the same seed gives the same
rays); every photon that escapes becomes one ray: where it leaves the luminaire's bounding
box, its direction and its flux (its emitter's flux over the emitter's photons). Positions
are in millimetres and directions in the luminaire prim's own frame, so a light carrying the
file (``lumitrace:rayFile``) with the luminaire's transform stands in for it at any
distance, near field included.
"""
from __future__ import annotations

import datetime
import os
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import LumitraceError
from ..run.session import allocate
from ..scene import Scene
from ..tm25 import RayFile, SIMULATION, header_texts, write_tm25
from ..trace.job import BatchJob, MAX_DEPTH
from ..trace.prepared import prepare
from ..trace.tracer import trace_batch

#: The most rays a file may hold by default (28 bytes each: 560 MB).
MAX_RAYS = 20_000_000
BATCH = 1 << 17


def exit_rays(scene: Scene, photons: int, seed: int = 0, max_depth: int = MAX_DEPTH
              ) -> RayFile:
    """The escaping rays of ``photons`` photons (shared by the emitters as by flux)."""
    ps = prepare(scene)
    pos, dirs, flux = [], [], []
    for k, (e, n) in enumerate(zip(scene.emitters, allocate([e.flux for e in scene.emitters],
                                                            photons))):
        for first in range(0, n, BATCH):
            t = trace_batch(ps, BatchJob(k, first, min(BATCH, n - first), seed, 1, max_depth),
                            exit_rays=True)
            p, d = t.exit_rays
            pos.append(p)
            dirs.append(d)
            flux.append(np.full(len(p), e.flux / n))
    p, d = np.concatenate(pos), np.concatenate(dirs)
    mpu = scene.meters_per_unit
    m = np.asarray(scene.luminaire_to_world, np.float64) if scene.luminaire_to_world \
        else np.diag([mpu, mpu, mpu, 1.0])  # luminaire stage units to world m
    inv = np.linalg.inv(m)
    local = (p - m[:3, 3]) @ inv[:3, :3].T * (mpu * 1000.0)
    turned = d @ inv[:3, :3].T
    turned /= np.linalg.norm(turned, axis=1, keepdims=True)
    name = scene.luminaire_path.rsplit("/", 1)[-1] or "luminaire"
    return RayFile(positions=local.astype(np.float32), directions=turned.astype(np.float32),
                   flux=np.concatenate(flux).astype(np.float32),
                   descriptions=(name, "", "", f"lumitrace {__version__}",
                                 "photon tracing of the USD stage", "",
                                 "", f"{photons} photons, seed {seed}",
                                 os.path.basename(scene.stage_path)),
                   creation_method=SIMULATION,
                   date=datetime.datetime.now().strftime("%Y-%m-%d %H:%M:%S"))


def claim_ray_file(path: str | os.PathLike, scene: Scene) -> None:
    """Refuse a ray file path that the stage reads (its own layers, a light's profile or
    rays) or that holds a file other than the exit rays lumitrace wrote for this stage."""
    path = Path(path)
    if os.path.realpath(path) in scene.input_files():
        raise LumitraceError("is a file the stage reads: the ray file would replace it; "
                             "name another (--out)", str(path))
    if not os.path.lexists(path):
        return
    texts = header_texts(path) if path.is_file() and not path.is_symlink() else None
    stage = os.path.basename(scene.stage_path)
    if texts is None or not texts[3].startswith("lumitrace ") or texts[8] != stage:
        raise LumitraceError(f"exists and is not a ray file lumitrace wrote for {stage}: "
                             "move it away or name another (--out)", str(path))


def write_exit_rays(path: str | os.PathLike, scene: Scene, photons: int, seed: int = 0,
                    max_rays: int = MAX_RAYS) -> RayFile:
    """Trace ``photons`` photons and write their exit rays to ``path`` (TM-25-13); only a
    path :func:`claim_ray_file` allows is written."""
    claim_ray_file(path, scene)
    if photons > max_rays:
        raise LumitraceError(f"{photons} photons could make more than the {max_rays} rays a "
                             "ray file may hold (28 bytes each); trace fewer", str(path))
    rays = exit_rays(scene, photons, seed)
    write_tm25(path, rays)
    return rays
