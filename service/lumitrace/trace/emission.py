"""Photon emission from UsdLux lights: start points and directions in world metres.

Every light is a Lambertian emitter of its surface (UsdLux): disk and rect lights emit from
one side, along their local -Z; sphere lights from their whole surface (isotropic
intensity); cylinder lights from their side, not their caps. UsdLuxShapingAPI narrows the
emission about the local -Z axis: intensity is multiplied by ``cos(theta)**focus`` and by a
cone window that is 1 inside ``angle * (1 - softness)``, falls with a smoothstep to 0 at
``angle`` and is 0 beyond. The authored luminous flux is the flux after shaping. A light
shaped by a measured profile (``shaping:ies:file``) emits that profile as its intensity
distribution (:mod:`lumitrace.trace.profiles`), from points spread over its surface. A
light with a TM-25 ray file (``lumitrace:rayFile``) emits the file's rays, in its own frame.
"""
from __future__ import annotations

import functools
import os

import numpy as np

from ..errors import LumitraceError
from ..scene import Emitter
from ..tm25 import read_tm25
from ..scene.shaping import is_one_sided, is_shaped, profile_table
from . import codes, compiled, rng
from .profiles import profile_table as measured_table

_SHAPES = {"disk": codes.DISK, "rect": codes.RECT, "sphere": codes.SPHERE,
           "cylinder": codes.CYLINDER, "mesh": codes.MESH}
_NO_TABLE = np.zeros(2)
_NO_ROWS = np.zeros((1, 2))
_NO_MESH = (np.array([0.0, 1.0]), np.zeros((1, 3, 3)), np.zeros((1, 3)))
_NO_RAYS = (np.array([0.0, 1.0]), np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]))


def _ray_tables(e: Emitter) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ray-file light's flux CDF over its rays and their start points (local units) and
    unit directions (re-read when the file changes)."""
    return _rays_of(e)[:3]


def ray_bands(e: Emitter) -> np.ndarray:
    """The tracing band of each ray of a light whose ray file gives per-ray wavelengths
    (-1 outside 380-780 nm, where the ray carries no luminous flux)."""
    return _rays_of(e)[3]


def _rays_of(e: Emitter) -> tuple:
    st = os.stat(e.rays)
    return _read_rays(e.rays, st.st_mtime_ns, st.st_size, float(e.ray_scale))


@functools.lru_cache(maxsize=4)
def _read_rays(path: str, _mtime_ns: int, _size: int, scale: float):
    """(flux CDF, start points, unit directions, bands or None) of a ray file, read once."""
    f = read_tm25(path)
    w = f.flux.astype(np.float64)
    bands = None
    if f.wavelengths is not None:
        from ..scene.spectra import BAND_OF, grid_indices, photopic

        if not f.photometric:  # drawn by luminous flux: every photon carries the same
            w = 683.0 * photopic(f.wavelengths) * f.radiant.astype(np.float64)
        nm, inside = grid_indices(f.wavelengths)
        bands = np.where(inside, BAND_OF[nm], -1)
    if not (len(f) and np.isfinite(w).all() and (w >= 0).all() and w.sum() > 0):
        raise LumitraceError("the ray file's rays carry no usable flux", path)
    cdf = np.concatenate([[0.0], np.cumsum(w)]) / w.sum()
    cdf[-1] = 1.0
    d = f.directions.astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return cdf, np.ascontiguousarray(f.positions.astype(np.float64) * scale), d, bands


def photon_bands(e: Emitter, hashes: np.ndarray, args: tuple) -> np.ndarray:
    """The band each photon (by its hash) of a per-ray-wavelength light starts in: that of
    the ray the emission kernel draws for it from its first number."""
    cdf = args[15]
    u1 = rng.uniforms_from(hashes, 0, 1)[0]
    t = np.clip(np.searchsorted(cdf, u1, side="right") - 1, 0, len(cdf) - 2)
    return ray_bands(e)[t]


def _mesh_tables(e: Emitter) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A mesh light's area CDF over its triangles, the triangles and their unit normals."""
    tri = np.ascontiguousarray(e.triangles, dtype=np.float64)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    cdf = np.concatenate([[0.0], np.cumsum(area)]) / area.sum()
    cdf[-1] = 1.0
    return cdf, tri, np.ascontiguousarray(cross / (2.0 * area[:, None]))


def emission_args(e: Emitter) -> tuple:
    """The light ``e`` as :func:`~lumitrace.trace.kernels.emit_photons` takes it: shape,
    sizes, point flag, shaping table, transform and normal transform."""
    if e.kind not in _SHAPES:
        raise ValueError(f"{e.path}: unknown emitter kind {e.kind!r}")
    m = np.asarray(e.to_world, dtype=np.float64)
    lin, t = np.ascontiguousarray(m[:3, :3]), np.ascontiguousarray(m[:3, 3])
    # normals transform with the inverse transpose; scaled first, so that a light in a stage
    # of tiny or huge units does not overflow (the reader refuses singular transforms)
    normal_map = np.ascontiguousarray(np.linalg.inv(lin / np.abs(lin).max()).T)
    measured = e.ies is not None
    shaped = not measured and e.kind != "mesh" and is_shaped(e.kind, e.cone_angle, e.focus)
    theta, cdf = (profile_table(1 if is_one_sided(e.kind) else 0, float(e.cone_angle),
                                float(e.cone_softness), float(e.focus))
                  if shaped else (_NO_TABLE, _NO_TABLE))
    m = measured_table(e.ies) if measured else None
    size = np.array([e.radius, e.width, e.height, e.length], dtype=np.float64)
    point = e.kind == "sphere" and (bool(e.treat_as_point) or e.radius == 0.0)
    mesh = _mesh_tables(e) if e.kind == "mesh" else _NO_MESH
    rays = _ray_tables(e) if e.rays is not None else _NO_RAYS
    shape = codes.RAYS if e.rays is not None else _SHAPES[e.kind]
    return (shape, size, point, shaped, theta, cdf, measured,
            m.c_cdf if m else _NO_TABLE, m.gamma_cdf if m else _NO_ROWS,
            m.cos_edges if m else _NO_TABLE, m.c_step if m else 1.0, *mesh,
            bool(e.two_sided), *rays, lin, t, normal_map)


#: The random draw (counter) that picks a group's light for a photon: far above the
#: draws of emission (0, 1) and of any bounce (4 per bounce up to the depth limit).
GROUP_DRAW = 1 << 20


def group_lights(e: Emitter, hashes: np.ndarray) -> np.ndarray:
    """Which light of the group ``e`` (index into its lights) each photon with hash
    ``hashes`` leaves from: drawn by the lights' shares of the flux."""
    u = rng.uniforms_from(hashes, GROUP_DRAW, 1)[0]
    cdf = np.cumsum(e.group.shares)
    return np.minimum(np.searchsorted(cdf, u * cdf[-1], side="right"), len(cdf) - 1)


def emit(e: Emitter, key: np.uint64, index: np.ndarray, normals: bool = False,
         out: tuple | None = None, args: tuple | None = None):
    """Start points (3, N; world m) and unit directions (3, N; world) of photons ``index``.

    Uses the random dimensions of bounce 0, so photon i of an emitter always starts the same.
    With ``normals`` also the unit normals (3, N; world) of the emitting surface at the start
    points, on the side the photons leave (a point light's are its directions): the tracer
    offsets ray origins along them, so that a photon leaving at a grazing angle does not
    start inside a part the light touches. ``out`` is (p, d, n, hashes) to fill instead of
    new arrays; ``args`` the light's :func:`emission_args`, when made already (a prepared
    scene makes them once, not per batch).
    """
    index = np.asarray(index, dtype=np.int64)
    k = index.shape[0]
    p, d, n, h = out if out is not None else (np.empty((3, k)), np.empty((3, k)),
                                              np.empty((3, k)), np.empty(k, np.uint64))
    compiled.emit_photons(*(args or emission_args(e)), np.uint64(key), index, p, d, n, h)
    if e.group is not None:  # each photon from one of the group's lights, drawn by share
        p += e.group.offsets[group_lights(e, h)].T
    if normals:
        return p, d, n
    return p, d
