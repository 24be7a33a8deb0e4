"""The luminaire as a near-field source: its own exit rays, from a trace.

Photons are traced through the luminaire as for its map (the same seed gives the same
rays); every photon that escapes becomes one ray: where it leaves the luminaire's bounding
box, its direction and its flux (its emitter's flux over the emitter's photons). Positions
are in millimetres and directions in the luminaire prim's own frame, so a light carrying the
file (``lumitrace:rayFile``) with the luminaire's transform stands in for it at any
distance, near field included. :mod:`lumitrace.publish.rays` writes them.
"""
from __future__ import annotations

import datetime
import os

import numpy as np

from .. import __version__
from ..scene import Scene
from ..tm25 import RayFile, SIMULATION
from .allocation import MIN_EMITTER_PHOTONS, allocate
from .job import BatchJob, MAX_DEPTH
from .prepared import prepare
from .tracer import trace_batch

#: Photons a batch of exit rays traces at once.
BATCH = 1 << 17


def escapes(scene: Scene, photons: int, seed: int = 0, max_depth: int = MAX_DEPTH
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the escaping photons of ``photons`` photons (shared by the emitters as by
    flux) leave the luminaire's box: positions (N, 3, world m), directions (N, 3, world)
    and flux (N, lm each). Photon k of an emitter is photon k of any run with ``seed``."""
    ps = prepare(scene)
    pos, dirs, flux = [], [], []
    for k, (e, n) in enumerate(zip(scene.emitters, allocate([e.flux for e in scene.emitters],
                                                            photons, MIN_EMITTER_PHOTONS))):
        for first in range(0, n, BATCH):
            t = trace_batch(ps, BatchJob(k, first, min(BATCH, n - first), seed, 1, max_depth),
                            exit_rays=True)
            p, d = t.exit_rays
            pos.append(p)
            dirs.append(d)
            flux.append(np.full(len(p), e.flux / n))
    if not pos:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(pos), np.concatenate(dirs), np.concatenate(flux)


def exit_rays(scene: Scene, photons: int, seed: int = 0, max_depth: int = MAX_DEPTH
              ) -> RayFile:
    """The escaping rays of ``photons`` photons (shared by the emitters as by flux)."""
    p, d, flux = escapes(scene, photons, seed, max_depth)
    mpu = scene.meters_per_unit
    m = np.asarray(scene.luminaire_to_world, np.float64) if scene.luminaire_to_world \
        else np.diag([mpu, mpu, mpu, 1.0])  # luminaire stage units to world m
    inv = np.linalg.inv(m)
    local = (p - m[:3, 3]) @ inv[:3, :3].T * (mpu * 1000.0)
    turned = d @ inv[:3, :3].T
    turned /= np.linalg.norm(turned, axis=1, keepdims=True)
    name = scene.luminaire_path.rsplit("/", 1)[-1] or "luminaire"
    return RayFile(positions=local.astype(np.float32), directions=turned.astype(np.float32),
                   flux=flux.astype(np.float32),
                   descriptions=(name, "", "", f"lumitrace {__version__}",
                                 "photon tracing of the USD stage", "",
                                 "", f"{photons} photons, seed {seed}",
                                 os.path.basename(scene.stage_path)),
                   creation_method=SIMULATION,
                   date=datetime.datetime.now().strftime("%Y-%m-%d %H:%M:%S"))
