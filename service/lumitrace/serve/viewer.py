"""What the live view page reads from the service: the preview of the current refinement,
the luminaire's triangles, the editable scene and the session's settings.

Maps and triangles travel as one binary frame: ``LTV1``, a little-endian uint32 length,
that many bytes of JSON header (padded to 4 bytes), then float32 arrays whose offsets
(bytes from the start of the data) and shapes the header gives. Everything is in the
photometric frame: x along C0, y along C90, z up (nadir is -z), metres and candela.
"""
from __future__ import annotations

import functools
import json
import math
import numbers
import struct
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import schema
from ..film.accumulate import flux_scale
from ..film.convergence import estimate
from ..film.cubemap import bilinear_taps, face_size, sample_map
from ..photometry import frame
from ..photometry.distribution import photometry_of
from ..photometry.quantities import scaled_figures
from ..photometry.ugr import ugr_table
from ..publish.record import defined
from ..scene import Scene

MAGIC = b"LTV1"
#: The lat-long view of the map: gamma rows (0 at nadir) by C columns, in degrees.
LATLONG_GAMMA = np.linspace(0.0, 180.0, 91)
LATLONG_C = np.linspace(0.0, 360.0, 181)
#: Triangles above which the page gets every k-th triangle of a part (stated in the header).
MAX_TRIANGLES = 150_000
#: The files the page is made of (served from the package, no network).
PAGE_DIR = Path(__file__).with_name("page")
PAGE_FILES = {"index.html": "text/html", "viewer.js": "text/javascript",
              "compare.js": "text/javascript", "fit.js": "text/javascript",
              "viewer.css": "text/css"}


def frame_bytes(header: dict[str, Any], arrays: dict[str, np.ndarray]) -> bytes:
    """One binary frame of ``arrays`` (as float32) with ``header`` (JSON)."""
    parts, layout, offset = [], {}, 0
    for name, a in arrays.items():
        data = np.ascontiguousarray(a, dtype="<f4")
        layout[name] = {"offset": offset, "shape": list(data.shape)}
        parts.append(data.tobytes())
        offset += data.nbytes
    text = json.dumps({**header, "arrays": layout}, allow_nan=False, default=str).encode()
    text += b" " * (-len(text) % 4)
    return MAGIC + struct.pack("<I", len(text)) + text + b"".join(parts)


def read_frame(data: bytes) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The header and arrays of a frame made by :func:`frame_bytes` (for clients, tests)."""
    if data[:4] != MAGIC:
        raise ValueError("not a lumitrace view frame")
    (n,) = struct.unpack_from("<I", data, 4)
    header = json.loads(data[8:8 + n])
    body = memoryview(data)[8 + n:]
    arrays = {}
    for name, spec in header["arrays"].items():
        count = int(np.prod(spec["shape"])) if spec["shape"] else 1
        arrays[name] = np.frombuffer(body, "<f4", count, spec["offset"]).reshape(spec["shape"])
    return header, arrays


def _photometric_points(scene: Scene, points: np.ndarray) -> np.ndarray:
    """World points (m) in the photometric frame, about the luminaire's origin."""
    axes = np.asarray(scene.photometric_axes)  # rows C0, C90, up
    m = np.asarray(scene.luminaire_to_world) if scene.luminaire_to_world else None
    origin = m[:3, 3] if m is not None else np.zeros(3)
    return (points - origin) @ axes.T


def geometry_frame(scene: Scene, revision: int) -> bytes:
    """The luminaire's triangles per part in the photometric frame (m), every k-th
    triangle of a scene above :data:`MAX_TRIANGLES` (the header says k)."""
    tri = np.asarray(scene.triangles, np.float64).reshape(-1, 3, 3)
    step = max(1, math.ceil(len(tri) / MAX_TRIANGLES))
    keep = np.arange(0, len(tri), step)
    local = _photometric_points(scene, tri[keep].reshape(-1, 3)).reshape(-1, 3, 3)
    part = np.asarray(scene.part_index)[keep]
    order = np.argsort(part, kind="stable")
    counts = np.bincount(part, minlength=len(scene.parts)).tolist() if len(part) else \
        [0] * len(scene.parts)
    emitters = [{"path": p, "position": q.tolist()} for e in scene.emitters
                for p, q in zip(e.light_paths, _photometric_points(scene, e.light_origins()))]
    header = {"revision": revision, "parts": list(scene.parts), "counts": counts,
              "triangles": int(len(tri)), "every": step, "emitters": emitters,
              "units": "m, photometric frame (x C0, y C90, z up)"}
    return frame_bytes(header, {"positions": local[order].reshape(-1, 3)})


@dataclass
class _Cached:
    key: tuple
    data: bytes
    #: what the frame was made of: the counts' version and lineage, the lights, header and
    #: arrays
    version: int
    lineage: int
    lights: tuple
    header: dict
    arrays: dict
    #: whether its figures hold the UGR (computed, even where undefined)
    ugr: bool = True


class PreviewCache:
    """The current preview frame, made once per (revision, photons, threshold)."""

    def __init__(self, kept=None) -> None:
        #: where every frame made is handed (:class:`~lumitrace.serve.reference.KeptFrames`)
        self.kept = kept
        self._lock = threading.Lock()
        # one frame is made at a time: requests arriving while it is made wait for it and
        # take it, rather than each making its own (and slowing every one down)
        self._making = threading.Lock()
        self._cached: _Cached | None = None

    def get(self, engine, hold: bool = True, ugr: bool = True) -> bytes | None:
        """The current preview frame of ``engine``; with ``hold`` (a client's request) the
        last frame while the engine is about to replace it (:meth:`Engine.preview_waits`),
        without (the engine's own refresh) always the current one. ``ugr`` False leaves
        the UGR figures out of a frame made now (an edit's first preview, which a designer
        waits for: they come with the next one)."""
        # the key first: a client polling an unchanged preview costs no copy of the counts
        key = engine.snapshot_key()
        if key is None:
            return None
        with self._lock:
            if self._cached is not None and self._cached.key == key and \
                    (self._cached.ugr or not ugr):
                return self._cached.data
        early = self._earlier_rescaled(engine, key)
        if early is not None:
            return early
        with self._lock:
            last = self._cached
        if last is not None and hold and engine.preview_waits():
            return last.data  # not a frame the engine is about to replace
        with self._making:
            snap = engine.snapshot()
            if snap is None:
                return None
            key = (snap["revision"], snap["photons"], snap["threshold"], snap["iteration"])
            with self._lock:
                last = self._cached
            if last is not None and last.key == key and (last.ugr or not ugr):
                return last.data
            acc = snap["accumulator"]
            lights = acc.light_state()
            k = flux_scale(last.lights, lights) if last is not None and \
                last.version == acc.version and last.key[2] == key[2] and \
                (last.ugr or not ugr) else None
            if k is not None:  # the same counts, every light dimmed alike: a rescale
                header, arrays = _rescaled(last.header, last.arrays, k, snap["revision"],
                                           snap["seconds"], iterations=snap["iteration"],
                                           target_error=snap["target"],
                                           converged=snap["converged"])
            else:
                header, arrays = preview_parts(**snap, ugr=ugr)
            data = frame_bytes(header, arrays)
            with self._lock:
                if self._cached is None or self._cached.key[0] <= key[0]:  # none newer
                    self._cached = _Cached(key, data, acc.version, acc.lineage, lights,
                                           header, arrays, last.ugr if k is not None else ugr)
            if self.kept is not None:
                self.kept.keep(header, data)
        return data

    def _earlier_rescaled(self, engine, key: tuple) -> bytes | None:
        """A new revision's first frame, where it is the last one's with every light
        dimmed alike: the last frame rescaled, of the photons it had (a preview of the new
        revision at those photons, as its counts do not depend on the flux). It serves
        until the next round's counts (once the revision is done: until the next request,
        which makes the frame of all its photons). None where that does not hold."""
        with self._lock:
            last = self._cached
        if last is None or last.key[0] == key[0] or last.key[2] != key[2]:
            return None
        basis = engine.preview_basis()
        if basis is None or basis[:2] != (key[0], last.lineage):
            return None
        revision, _, lights, done = basis
        k = flux_scale(last.lights, lights)
        if k is None:
            return None
        header, arrays = _rescaled(last.header, last.arrays, k, revision,
                                   last.header["seconds"])
        data = frame_bytes(header, arrays)
        with self._lock:
            if self._cached is last:  # no newer frame was made meanwhile
                self._cached = _Cached((revision, *last.key[1:]) if done else key, data,
                                       last.version, last.lineage, lights, header, arrays,
                                       last.ugr)
        if self.kept is not None:
            self.kept.keep(header, data)
        return data


@functools.lru_cache(maxsize=8)
def _latlong_taps_of(up_axis: str, rotation: tuple, res: int):
    cc, gg = np.meshgrid(LATLONG_C, LATLONG_GAMMA)
    turn = np.asarray(rotation).reshape(3, 3) if rotation else ()
    dirs = frame.directions(cc, gg, up_axis, turn).reshape(-1, 3)
    return bilinear_taps(dirs, res)


def _latlong_taps(scene: Scene, res: int):
    """The cube-map lookups of the lat-long view's directions (made once per frame)."""
    rotation = frame.luminaire_rotation(scene)
    key = tuple(np.asarray(rotation, np.float64).ravel().tolist()) if len(rotation) else ()
    return _latlong_taps_of(scene.up_axis, key, res)


def _rescaled(header: dict, arrays: dict, k: float, revision: int, seconds: float,
              **changes) -> tuple[dict, dict]:
    """A preview's header and arrays for the same counts with every light's flux times
    ``k``, as revision ``revision`` (and the header's fields ``changes``): intensities and
    fluxes scale, angles and relative errors stay."""
    figures = scaled_figures(header["figures"], k)
    for key in UGR_KEYS[::2]:  # L^2 omega / Lb scales with k: UGR moves by 8 log10 k
        if figures.get(key) is not None:
            figures[key] += 8.0 * math.log10(k)
    header = {**header, **changes, "revision": revision, "seconds": seconds,
              "lamp_lumens": header["lamp_lumens"] * k, "figures": figures}
    return header, {name: a * k for name, a in arrays.items()}


def preview_parts(scene: Scene, accumulator, estimate_, revision: int, photons: int,
                  iteration: int, threshold: float, target: float,
                  converged: bool, seconds: float, seed: int, ugr: bool = True
                  ) -> tuple[dict, dict]:
    """The header and arrays of a refinement's preview (an
    :meth:`~lumitrace.serve.engine.Engine.snapshot`): the map (filtered and raw, cd) on a
    lat-long grid in the photometric frame, the published C-gamma grid (cd) with its
    standard errors, and the figures, tagged with revision and photons. The luminous
    opening is measured with the session's ``seed``, as for its files."""
    est = estimate_ if estimate_ is not None and estimate_.threshold == threshold \
        else estimate(accumulator, threshold)
    ph = photometry_of(scene, accumulator, seed)
    full = ph.grid.full()
    taps = _latlong_taps(scene, face_size(est.filtered.shape[0]))
    shape = (len(LATLONG_GAMMA), len(LATLONG_C))
    both = np.stack([est.filtered, est.raw], axis=-1)
    filtered, raw = (m.reshape(shape) for m in sample_map(both, None, taps).T)
    fig = {**ph.figures.as_dict(),
           **(catalogue_ugr(ph) if ugr else dict.fromkeys(UGR_KEYS))}
    header = {
        "revision": revision, "photons": photons, "iterations": iteration,
        "seconds": seconds, "threshold": threshold, "target_error": target,
        "relative_error": defined(est.error), "relative_error_bound": defined(est.error_bound),
        "raw_relative_error": defined(est.raw_error), "stepped_back": bool(est.stepped_back),
        "converged": converged, "lamp_lumens": ph.lamp_flux, "symmetry": ph.grid.symmetry,
        "symmetry_source": ph.symmetry.source,
        "c": full.c.tolist(), "gamma": full.gamma.tolist(),
        "latlong": {"c": LATLONG_C.tolist(), "gamma": LATLONG_GAMMA.tolist()},
        "figures": {k: _plain(v) for k, v in fig.items()},
        "units": {"map": "cd", "grid": "cd", "sigma": "cd"},
    }
    sigma = full.sigma if full.sigma is not None else np.zeros_like(full.candela)
    return header, {"filtered": filtered, "raw": raw, "grid": full.candela, "sigma": sigma}


#: The UGR figures a preview carries (4H x 8H, 70/50/20, crosswise and endwise), each
#: followed by its standard error.
UGR_KEYS = ("ugr_4h8h_70_50_20", "ugr_4h8h_70_50_20_error", "ugr_4h8h_70_50_20_endwise",
            "ugr_4h8h_70_50_20_endwise_error")
#: The last photometry whose UGR was computed and its UGR figures, as one pair.
_LAST_UGR: list = [None]


def catalogue_ugr(ph) -> dict[str, float | None]:
    """The catalogue UGR figures (:data:`UGR_KEYS`) of a
    :class:`~lumitrace.photometry.distribution.Photometry` (None where its opening has no
    area or no light leaves), computed once per photometry (a few ms)."""
    last = _LAST_UGR[0]  # read once: another thread may replace it meanwhile
    if last is not None and last[0] is ph:
        return last[1]
    out = dict.fromkeys(UGR_KEYS)
    if (ph.opening.area > 0 or ph.opening.height > 0) and ph.figures.luminous_flux > 0:
        table = ugr_table(ph.grid, ph.opening).as_dict()
        out = {k: defined(table[k]) for k in UGR_KEYS}
    _LAST_UGR[0] = (ph, out)
    return out


def _plain(value: Any) -> Any:
    """A figure as JSON holds it: numbers as floats (None where undefined), tuples as
    lists."""
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, str)) or value is None:
        return value
    if isinstance(value, numbers.Real):
        return defined(float(value))
    return str(value)


def editable_scene(scene: Scene, revision: int,
                   transforms: dict[str, dict] | None = None) -> dict[str, Any]:
    """The parts (with their local ``transforms`` where given:
    :func:`~lumitrace.serve.transforms.part_transforms`), their materials (the prim that
    holds each material's values, and the values), the emitters and their fluxes, with the
    ranges a delta must respect."""
    index = np.asarray(scene.material_index)
    part = np.asarray(scene.part_index)
    parts = []
    for k, name in enumerate(scene.parts):
        mats = sorted(set(index[part == k].tolist()))
        parts.append({"path": name, "materials": [scene.materials[m].path for m in mats],
                      "triangles": int((part == k).sum()),
                      "transform": (transforms or {}).get(name)})
    materials = [{"path": m.path, "scattering": m.scattering, "reflectance": m.reflectance,
                  "specularReflectance": m.specular_reflectance,
                  "transmittance": m.transmittance, "ior": m.ior, "roughness": m.roughness,
                  "editable": bool(m.path)}  # the fallback material has no prim
                 for m in scene.materials]
    ranges = {name.split(":", 1)[1]: list(r) for name, r in schema.MATERIAL_RANGES.items()}
    ranges["ior"] = [schema.IOR_EXCLUSIVE_MIN, None]
    return {"revision": revision, "parts": parts, "materials": materials,
            "emitters": [{"path": e.path, "kind": e.kind, "flux": e.flux,
                          "editable": "[" not in e.path,
                          "lights": len(e.light_paths)} for e in scene.emitters],
            "properties": {"scattering": schema.SCATTERING, "reflectance": schema.REFLECTANCE,
                           "specularReflectance": schema.SPECULAR_REFLECTANCE,
                           "transmittance": schema.TRANSMITTANCE, "ior": schema.IOR,
                           "roughness": schema.ROUGHNESS, "flux": schema.LUMINOUS_FLUX},
            "scattering_models": list(schema.SCATTERING_TOKENS), "ranges": ranges,
            "ior_exclusive_min": schema.IOR_EXCLUSIVE_MIN}
