"""Emitters: ``UsdLux`` Sphere, Disk, Rect and Cylinder lights read into
:class:`~lumitrace.scene.Emitter` s, their shaping, world area and luminous flux."""
from __future__ import annotations

import math
import os
from dataclasses import fields
from typing import Callable

import numpy as np
from pxr import Sdf, Usd, UsdGeom, UsdLux

from .. import schema
from ..digests import file_stamp
from .colour import light_spectrum, ray_file_colour
from ..errors import StageError
from ..scene import Emitter, IesShaping
from .. import tm25
from ..scene.shaping import shaping_emits, shaping_fraction, unshaped_cone_angle
from . import validate
from .materials import luminance
from .transforms import Frame, invertible, placements, raise_bad_transform
from .validate import check_array

_LIGHT_TYPES = (
    (UsdLux.SphereLight, "sphere"),
    (UsdLux.DiskLight, "disk"),
    (UsdLux.RectLight, "rect"),
    (UsdLux.CylinderLight, "cylinder"),
)
_EMITTER_FIELDS = {f.name for f in fields(Emitter)}


def light_flux(kind: str, intensity: float, exposure: float = 0.0,
               color=(1.0, 1.0, 1.0), normalize: bool = False, area: float = 1.0,
               fraction: float = 1.0) -> float:
    """Luminous flux (lm) of a UsdLux light from its intensity inputs.

    The luminance is ``L = intensity * 2**exposure * Y(color)`` (nits); a Lambertian
    surface of world area ``A`` (m^2; one side of a disk or rect, the whole sphere, the
    cylinder's side without caps) emits ``pi * L * A``; ``normalize`` divides the area
    out: ``pi * L``. ``fraction`` is the shaping fraction (:func:`shaping_fraction`).
    A colour temperature does not change the flux: UsdLux's blackbody colour is
    normalised to luminance 1.
    """
    del kind  # same formula for every kind once the area is known
    with np.errstate(over="ignore"):  # a huge exposure is an infinite flux, refused later
        lum = intensity * float(np.exp2(exposure)) * luminance(color)
    return math.pi * lum * (1.0 if normalize else area) * fraction


def light_kind(prim: Usd.Prim) -> str | None:
    """The emitter kind of a supported light prim, else None."""
    for light_type, kind in _LIGHT_TYPES:
        if prim.IsA(light_type):
            return kind
    return None


def read_light(prim: Usd.Prim, kind: str, frame: Frame, xf: UsdGeom.XformCache,
               meters_per_unit: float, warn: Callable[[str], None]) -> list[Emitter]:
    """The emitters of a light of ``kind``, one per placement of ``prim`` in ``frame``, read
    at the time of ``xf``."""
    time = xf.GetTime()
    path = str(prim.GetPath())
    light = UsdLux.LightAPI(prim)
    dims: dict[str, float | bool] = {}
    if kind == "sphere":
        sphere = UsdLux.SphereLight(prim)
        dims["radius"] = validate.check_non_negative(
            sphere.GetRadiusAttr().Get(time), path, "inputs:radius")
        dims["treat_as_point"] = bool(sphere.GetTreatAsPointAttr().Get(time))
    elif kind == "disk":
        dims["radius"] = validate.check_positive(
            UsdLux.DiskLight(prim).GetRadiusAttr().Get(time), path, "inputs:radius")
    elif kind == "rect":
        rect = UsdLux.RectLight(prim)
        dims["width"] = validate.check_positive(rect.GetWidthAttr().Get(time), path,
                                                "inputs:width")
        dims["height"] = validate.check_positive(rect.GetHeightAttr().Get(time), path,
                                                 "inputs:height")
        if rect.GetTextureFileAttr().Get(time):
            warn(f"{path}.inputs:texture:file: light textures are ignored")
    else:
        cylinder = UsdLux.CylinderLight(prim)
        dims["length"] = validate.check_positive(cylinder.GetLengthAttr().Get(time),
                                                 path, "inputs:length")
        dims["radius"] = validate.check_positive(cylinder.GetRadiusAttr().Get(time),
                                                 path, "inputs:radius")
    cone_angle, cone_softness, focus, ies = _shaping(prim, kind, time, warn)
    rays = _ray_file(prim, time)
    if rays is not None and (ies is not None or cone_angle < unshaped_cone_angle(kind)
                             or focus > 0.0):
        warn(f"{path}: a light that emits a ray file is not shaped: its shaping is ignored")
        cone_angle, cone_softness, focus, ies = unshaped_cone_angle(kind), 0.0, 0.0, None

    spectrum = light_spectrum(prim, light, time)
    ray_bands, ray_lumens = False, None
    if rays is not None:
        ray_set = tm25.read_tm25(rays)
        file_spectrum, ray_lumens = ray_file_colour(ray_set, rays)
        if file_spectrum and not spectrum:  # rays with wavelengths of their own: theirs
            spectrum, ray_bands = file_spectrum, True
    flux_attr = prim.GetAttribute(schema.LUMINOUS_FLUX)
    authored_flux = None
    if flux_attr and flux_attr.HasAuthoredValue():
        authored_flux = validate.check_luminous_flux(flux_attr.Get(time), path,
                                                     schema.LUMINOUS_FLUX)
    if rays is not None:
        stated, ray_extent = tm25.summary(ray_set)
        if authored_flux is None:
            if stated is None:  # radiometric: luminous where the rays give wavelengths
                stated = ray_lumens
            if stated is None:
                raise StageError("the ray file carries radiant flux only: author "
                                 "lumitrace:luminousFlux (lm)", path, schema.RAY_FILE)
            authored_flux = validate.check_luminous_flux(stated, path, schema.RAY_FILE)
    if authored_flux is None:
        if not light.GetIntensityAttr().HasAuthoredValue():
            raise StageError("light has no luminous flux: author lumitrace:luminousFlux "
                             "(lm) or inputs:intensity", path)
        intensity, exposure, color, normalize = _intensity_inputs(light, time, path)
        fraction = shaping_fraction(kind, cone_angle, cone_softness, focus)
        if ies is not None and not ies.normalize:
            warn(f"{path}.inputs:shaping:ies:normalize: an IES profile that is not "
                 "normalised scales the light's power by the renderer's convention; the "
                 "light is traced with its unshaped flux (author lumitrace:luminousFlux "
                 "or ies:normalize to say which flux it has)")

    emitters = []
    for matrix, label in placements(xf, prim, frame):
        to_world = np.diag([meters_per_unit] * 3 + [1.0]) @ matrix.T
        validate.check_extent(to_world[:3, 3], path, "xformOpOrder")
        validate.check_extent(np.abs(to_world[:3, :3]).sum(axis=0) * max(
            v for v in dims.values() if not isinstance(v, bool)), path, "xformOpOrder")
        if not invertible(matrix[:3, :3]):
            raise_bad_transform(prim, time, singular=True)
        if authored_flux is not None:
            flux = authored_flux
        else:
            area = _world_area(kind, dims, to_world[:3, :3])
            flux = light_flux(kind, intensity, exposure, color, normalize, area, fraction)
            if flux > validate.MAX_LUMINOUS_FLUX:  # Inf too; NaN is refused below
                validate.check_flux_limit(
                    flux, path, _flux_source(kind, intensity, exposure, color, normalize,
                                             area, fraction),
                    f"luminous flux from intensity {intensity:g}, exposure {exposure:g}, "
                    f"world area {area:g} m^2")
            if not (math.isfinite(flux) and flux > 0.0):
                raise StageError(f"light emits no {'finite ' if flux else ''}flux "
                                 f"({flux:g} lm from intensity "
                                 f"{intensity:g}, exposure {exposure:g}, world area "
                                 f"{area:g} m^2)", path, "inputs:intensity")
        extra = {"focus": focus} if "focus" in _EMITTER_FIELDS else {}
        emitters.append(Emitter(
            path=path + label, kind=kind, flux=float(flux), to_world=to_world,
            spectrum=spectrum, ray_bands=ray_bands,
            cone_angle=cone_angle, cone_softness=cone_softness, ies=ies, rays=rays,
            ray_scale=0.001 / meters_per_unit, rays_stamp=file_stamp(rays) if rays else "",
            ray_extent=tuple(ray_extent * 0.001 / meters_per_unit) if rays else (),
            **dims, **extra))
    return emitters


def _intensity_inputs(light: UsdLux.LightAPI, time: Usd.TimeCode, path: str
                      ) -> tuple[float, float, np.ndarray, bool]:
    """A light's UsdLux intensity, exposure, colour and normalize, checked."""
    intensity = validate.check_non_negative(light.GetIntensityAttr().Get(time), path,
                                            "inputs:intensity")
    exposure = validate.check_finite(light.GetExposureAttr().Get(time), path,
                                     "inputs:exposure")
    color = check_array(light.GetColorAttr().Get(time), path, "inputs:color", width=3).ravel()
    if color.size != 3 or not np.isfinite(color).all() or (color < 0).any():
        raise StageError(f"must be finite and >= 0, got {tuple(color)}", path, "inputs:color")
    return intensity, exposure, color, bool(light.GetNormalizeAttr().Get(time))


def read_mesh_light(prim: Usd.Prim, placed: list[np.ndarray], time: Usd.TimeCode,
                    warn: Callable[[str], None]) -> list[Emitter]:
    """The emitters of a gprim with UsdLux MeshLightAPI (or the older GeometryLight's
    LightAPI), one per placement: its world triangles (``placed``, m) emit as a Lambertian
    surface from their front faces, or both sides for a ``doubleSided`` gprim. The flux is
    ``lumitrace:luminousFlux`` or, from ``inputs:intensity``, pi L A per side."""
    path = str(prim.GetPath())
    two_sided = bool(UsdGeom.Gprim(prim).GetDoubleSidedAttr().Get(time))
    if prim.HasAPI(UsdLux.ShapingAPI):
        warn(f"{path}: shaping of a mesh light is ignored")
    flux_attr = prim.GetAttribute(schema.LUMINOUS_FLUX)
    light = UsdLux.LightAPI(prim)
    spectrum = light_spectrum(prim, light, time)
    emitters = []
    for k, tris in enumerate(placed):
        if len(tris) == 0:
            continue
        area = float(0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0],
                                                     tris[:, 2] - tris[:, 0]), axis=1).sum())
        if flux_attr and flux_attr.HasAuthoredValue():
            flux = validate.check_luminous_flux(flux_attr.Get(time), path,
                                                schema.LUMINOUS_FLUX)
        elif light.GetIntensityAttr().HasAuthoredValue():
            intensity, exposure, color, normalize = _intensity_inputs(light, time, path)
            flux = light_flux("mesh", intensity, exposure, color, normalize, area,
                              2.0 if two_sided else 1.0)
            if not (math.isfinite(flux) and 0.0 < flux <= validate.MAX_LUMINOUS_FLUX):
                raise StageError(f"mesh light emits no usable flux ({flux:g} lm)", path,
                                 "inputs:intensity")
        else:
            raise StageError("light has no luminous flux: author lumitrace:luminousFlux (lm) "
                             "or inputs:intensity", path)
        centre = tris.reshape(-1, 3).mean(axis=0)
        to_world = np.eye(4)
        to_world[:3, 3] = centre
        emitters.append(Emitter(path=path + (f"[{k}]" if len(placed) > 1 else ""),
                                kind="mesh", flux=float(flux), to_world=to_world,
                                spectrum=spectrum,
                                triangles=np.ascontiguousarray(tris - centre),
                                two_sided=two_sided))
    return emitters


def _flux_source(kind: str, intensity: float, exposure: float, color, normalize: bool,
                 area: float, fraction: float) -> str:
    """The input that takes a light's flux above :data:`.validate.MAX_LUMINOUS_FLUX`: the
    exposure, if the flux is within the limit without it, else the colour, if its
    luminance above 1 is what does it, else the intensity."""
    if exposure > 0.0 and light_flux(kind, intensity, 0.0, color, normalize, area,
                                      fraction) <= validate.MAX_LUMINOUS_FLUX:
        return "inputs:exposure"
    if luminance(color) > 1.0 and light_flux(kind, intensity, exposure, (1.0, 1.0, 1.0),
                                             normalize, area, fraction) \
            <= validate.MAX_LUMINOUS_FLUX:
        return "inputs:color"
    return "inputs:intensity"


def _shaping(prim: Usd.Prim, kind: str, time: Usd.TimeCode, warn: Callable[[str], None]
             ) -> tuple[float, float, float, IesShaping | None]:
    """Cone angle (deg), softness, focus and IES profile; unshaped: 90 deg for one-sided
    lights, 180 deg (all directions) for sphere and cylinder lights. An IES profile is the
    light's whole distribution: the cone and focus do not apply to it."""
    path = str(prim.GetPath())
    unshaped = unshaped_cone_angle(kind)
    if not prim.HasAPI(UsdLux.ShapingAPI):
        return unshaped, 0.0, 0.0, None
    shaping = UsdLux.ShapingAPI(prim)
    angle_attr = shaping.GetShapingConeAngleAttr()
    angle, softness, focus = unshaped, 0.0, 0.0
    if angle_attr.HasAuthoredValue():
        angle = validate.check_positive(angle_attr.Get(time), path,
                                        "inputs:shaping:cone:angle")
        angle = min(angle, 180.0)
    softness_attr = shaping.GetShapingConeSoftnessAttr()
    if softness_attr.HasAuthoredValue():
        softness = min(validate.check_non_negative(softness_attr.Get(time), path,
                                                   "inputs:shaping:cone:softness"), 1.0)
    focus_attr = shaping.GetShapingFocusAttr()
    if focus_attr.HasAuthoredValue():
        focus = validate.check_non_negative(focus_attr.Get(time), path,
                                            "inputs:shaping:focus")
    ies = _ies_shaping(shaping, kind, time, path, warn)
    if ies is not None:
        if angle < unshaped or focus > 0.0:
            warn(f"{path}: the cone and focus do not apply to a light shaped by an IES "
                 "profile: ignored")
        return unshaped, 0.0, 0.0, ies
    if kind == "cylinder" and (angle < unshaped or focus > 0.0):
        warn(f"{path}: shaping of a CylinderLight is ignored")
        return unshaped, 0.0, 0.0, None
    if focus > 0.0 and "focus" not in _EMITTER_FIELDS:
        warn(f"{path}.inputs:shaping:focus: focus is not supported: ignored")
        focus = 0.0
    if not shaping_emits(kind, angle, softness, focus):
        raise StageError("shaping leaves no direction to emit in (cone angle, softness and "
                         "focus together)", path,
                         "inputs:shaping:focus" if focus > 0.0 else "inputs:shaping:cone:angle")
    return angle, softness, focus, None


#: Segments round a light body's disk, sphere or cylinder.
BODY_SEGMENTS = 64


def has_body(prim: Usd.Prim, time: Usd.TimeCode) -> bool:
    """Whether the light's own surface is geometry too (``lumitrace:body``)."""
    attr = prim.GetAttribute(schema.BODY)
    return bool(attr and attr.HasAuthoredValue() and attr.Get(time))


def body_triangles(kind: str, dims: dict) -> np.ndarray:
    """The surface (T, 3, 3) of a light of ``kind`` with sizes ``dims``, local units, front
    faces toward where it emits: a disk or rect in its XY plane facing -Z, a sphere, a
    cylinder along X with its caps (a closed package). The polygons are inscribed: every
    emitted photon starts on or outside them."""
    n = BODY_SEGMENTS
    phi = 2.0 * np.pi * np.arange(n) / n
    ring = np.c_[np.cos(phi), np.sin(phi)]
    if kind == "disk":
        r = dims["radius"]
        p = np.c_[r * ring, np.zeros(n)]
        return np.stack([np.zeros((n, 3)), np.roll(p, -1, axis=0), p], axis=1)
    if kind == "rect":
        w, h = 0.5 * dims["width"], 0.5 * dims["height"]
        c = np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]])
        return np.stack([c[[0, 2, 1]], c[[0, 3, 2]]])
    if kind == "sphere":
        r = dims["radius"]
        theta = np.pi * np.arange(n // 2 + 1) / (n // 2)
        v = np.stack([np.sin(theta)[:, None] * ring[None, :, 0],
                      np.sin(theta)[:, None] * ring[None, :, 1],
                      np.repeat(np.cos(theta)[:, None], n, axis=1)], axis=-1) * r
        a, b = v[:-1], v[1:]
        a1, b1 = np.roll(a, -1, axis=1), np.roll(b, -1, axis=1)
        tri = np.concatenate([np.stack([a, b, b1], 2), np.stack([a, b1, a1], 2)])
        tri = tri.reshape(-1, 3, 3)
        area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        return tri[area > 1e-12 * r * r]  # the poles' degenerate triangles
    r, half = dims["radius"], 0.5 * dims["length"]
    yz = r * ring
    left = np.c_[np.full(n, -half), yz]
    right = np.c_[np.full(n, half), yz]
    l1, r1 = np.roll(left, -1, axis=0), np.roll(right, -1, axis=0)
    side = np.concatenate([np.stack([left, l1, r1], 1), np.stack([left, r1, right], 1)])
    caps = np.concatenate([np.stack([np.tile([-half, 0, 0], (n, 1)), l1, left], 1),
                           np.stack([np.tile([half, 0, 0], (n, 1)), right, r1], 1)])
    return np.concatenate([side, caps])


def _ray_file(prim: Usd.Prim, time: Usd.TimeCode) -> str | None:
    """The TM-25 ray file a light emits (``lumitrace:rayFile``), resolved beside the layer
    that authors it, or None."""
    attr = prim.GetAttribute(schema.RAY_FILE)
    asset = attr.Get(time) if attr and attr.HasAuthoredValue() else None
    if not asset or not asset.path:
        return None
    return _existing_file(asset, "ray file", str(prim.GetPath()), schema.RAY_FILE)


def _existing_file(asset: Sdf.AssetPath, what: str, path: str, prop: str) -> str:
    """The absolute path of a file an attribute names, resolved beside the layer that
    authors it; a StageError naming the attribute where there is no such file."""
    resolved = asset.resolvedPath
    if not resolved or not os.path.isfile(resolved):
        raise StageError(f"{what} not found: {asset.path}", path, prop)
    return os.path.abspath(resolved)


def _ies_shaping(shaping: UsdLux.ShapingAPI, kind: str, time: Usd.TimeCode, path: str,
                 warn: Callable[[str], None]) -> IesShaping | None:
    """The light's IES profile, its file resolved and checked to exist (its content is
    read when the scene is prepared for tracing)."""
    asset = shaping.GetShapingIesFileAttr().Get(time)
    if not asset or not asset.path:
        return None
    prop = "inputs:shaping:ies:file"
    if kind == "cylinder":
        warn(f"{path}.{prop}: IES profiles on a CylinderLight are ignored")
        return None
    resolved = _existing_file(asset, "IES profile", path, prop)
    scale_attr = shaping.GetShapingIesAngleScaleAttr()
    scale = float(scale_attr.Get(time)) if scale_attr.HasAuthoredValue() else 0.0
    if not (math.isfinite(scale) and scale > -1.0):
        raise StageError(f"must be finite and > -1, got {scale:g}", path,
                         "inputs:shaping:ies:angleScale")
    return IesShaping(resolved, scale,
                      bool(shaping.GetShapingIesNormalizeAttr().Get(time)),
                      file_stamp(resolved))


def _cofactor(a: np.ndarray) -> np.ndarray:
    """Cofactor matrix of a 3x3 linear map: ``C @ n`` is the area vector that a unit area
    with normal ``n`` maps to (valid for singular maps too)."""
    c = np.empty((3, 3))
    for i in range(3):
        c[:, i] = np.cross(a[:, (i + 1) % 3], a[:, (i + 2) % 3])
    return c


def _world_area(kind: str, dims: dict, linear: np.ndarray) -> float:
    """World area (m^2) of a light's emitting surface under the local-to-world map."""
    c = _cofactor(linear)
    if kind == "disk":
        return math.pi * dims["radius"] ** 2 * float(np.linalg.norm(c[:, 2]))
    if kind == "rect":
        return dims["width"] * dims["height"] * float(np.linalg.norm(c[:, 2]))
    if kind == "cylinder":  # side only; axis along local X
        phi = np.linspace(0.0, 2.0 * math.pi, 256, endpoint=False)
        normals = np.stack([np.zeros_like(phi), np.cos(phi), np.sin(phi)])
        ring = float(np.mean(np.linalg.norm(c @ normals, axis=0))) * 2.0 * math.pi
        return dims["radius"] * dims["length"] * ring
    # sphere: integrate |C n| over the unit sphere (Gauss-Legendre in cos(theta))
    mu, weights = np.polynomial.legendre.leggauss(48)
    phi = np.linspace(0.0, 2.0 * math.pi, 96, endpoint=False)
    s = np.sqrt(1.0 - mu ** 2)
    normals = np.stack([np.outer(s, np.cos(phi)), np.outer(s, np.sin(phi)),
                        np.outer(mu, np.ones_like(phi))]).reshape(3, -1)
    integrand = np.linalg.norm(c @ normals, axis=0).reshape(mu.size, phi.size)
    solid = float(np.sum(weights[:, None] * integrand) * (2.0 * math.pi / phi.size))
    return dims["radius"] ** 2 * solid
