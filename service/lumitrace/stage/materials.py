"""Materials of gprims: bindings (per gprim and per GeomSubset face), the
``UsdPreviewSurface`` mapping and the ``LumitraceMaterialAPI`` values layered over it."""
from __future__ import annotations

import dataclasses
from typing import Callable, Iterable

import numpy as np
from pxr import Usd, UsdShade

from .. import schema
from ..scene import Material
from . import validate
from .colour import surface_spectra
from .validate import Sourced, check_array

#: Rec.709 / sRGB luminance weights (linear RGB -> relative luminance Y).
REC709_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: Key of the UsdPreviewSurface colour behind an albedo (its spectral shape) among the
#: values :func:`preview_values` returns.
PREVIEW_COLOUR = "preview:colour"

#: Path of the default material given to gprims with no material (no prim has it).
DEFAULT_MATERIAL_PATH = ""

#: UsdPreviewSurface mapping thresholds (see :func:`preview_surface_values`).
METALLIC_THRESHOLD = 0.5
MIRROR_ROUGHNESS = 0.05
SPECULAR_WORKFLOW_THRESHOLD = 0.5


def luminance(rgb: Iterable[float]) -> float:
    """Relative luminance Y of a linear Rec.709 RGB colour."""
    return float(np.dot(REC709_LUMINANCE, np.asarray(tuple(rgb), dtype=np.float64)))


def preview_surface_values(diffuse_color=(0.18, 0.18, 0.18), metallic: float = 0.0,
                           roughness: float = 0.5, opacity: float = 1.0, ior: float = 1.5,
                           use_specular_workflow: int = 0,
                           specular_color=(0.0, 0.0, 0.0)) -> dict[str, float | str]:
    """Photometric material values derived from ``UsdPreviewSurface`` inputs.

    Defaults are UsdPreviewSurface's. The mapping, first match wins:

    1. ``opacity < 1``: ``dielectric`` with ``ior`` = inputs:ior and ``transmittance``
       (internal, per crossing) = 1 - opacity;
    2. specular workflow (``useSpecularWorkflow = 1``, metallic ignored) with
       Y(specularColor) >= 0.5, or metallic workflow with ``metallic > 0.5``: a metal,
       ``mirror`` when roughness < 0.05 else ``glossy`` with that roughness;
       ``specularReflectance`` = Y(specularColor) resp. Y(diffuseColor) (a metal's base
       colour is its reflectance);
    3. otherwise ``diffuse`` with ``reflectance`` = Y(diffuseColor).

    Y is the Rec.709 luminance, clipped to [0, 1], as is roughness. Returns only the
    values the mapping sets, keyed by lumitrace attribute name.
    """
    y_diffuse = float(np.clip(luminance(diffuse_color), 0.0, 1.0))
    y_specular = float(np.clip(luminance(specular_color), 0.0, 1.0))
    rough = float(np.clip(roughness, 0.0, 1.0))
    if opacity < 1.0:
        return {schema.SCATTERING: "dielectric", schema.IOR: float(ior),
                schema.TRANSMITTANCE: float(np.clip(1.0 - opacity, 0.0, 1.0))}
    if use_specular_workflow:
        metal, albedo = y_specular >= SPECULAR_WORKFLOW_THRESHOLD, y_specular
    else:
        metal, albedo = metallic > METALLIC_THRESHOLD, y_diffuse
    if metal:
        if rough < MIRROR_ROUGHNESS:
            return {schema.SCATTERING: "mirror", schema.SPECULAR_REFLECTANCE: albedo}
        return {schema.SCATTERING: "glossy", schema.SPECULAR_REFLECTANCE: albedo,
                schema.ROUGHNESS: rough}
    return {schema.SCATTERING: "diffuse", schema.REFLECTANCE: y_diffuse}


class BoundMaterials:
    """The materials bound to the gprims read so far, each read once: ``materials[i]`` is
    the material of index ``i``, ``unbound`` lists the gprims that got the default one."""

    def __init__(self, time: Usd.TimeCode, warn: Callable[[str], None]):
        self.time = time
        self.warn = warn
        self.index: dict[str, int] = {}
        self.materials: list[Material] = []
        self.unbound: list[str] = []

    def face_materials(self, prim: Usd.Prim, n_faces: int) -> np.ndarray:
        """Material index of each face of a gprim (GeomSubset bindings per face)."""
        face_material = np.full(n_faces, self.material_for(prim, prim), dtype=np.int32)
        binding = UsdShade.MaterialBindingAPI(prim)
        for subset in binding.GetMaterialBindSubsets():
            subset_prim = subset.GetPrim()
            if not subset_prim.IsActive():
                continue
            faces = check_array(subset.GetIndicesAttr().Get(self.time),
                                str(subset_prim.GetPath()), "indices", np.int64)
            inside = faces[(faces >= 0) & (faces < n_faces)]
            if inside.size != faces.size:
                self.warn(f"{subset_prim.GetPath()}: {faces.size - inside.size} indices "
                          "outside the mesh's faces ignored")
            face_material[inside] = self.material_for(prim, subset_prim)
        return face_material

    def material_for(self, gprim: Usd.Prim, bind_prim: Usd.Prim) -> int:
        """Index of the material of ``bind_prim`` (the gprim or one of its subsets)."""
        gprim_path = str(gprim.GetPath())
        material, _ = UsdShade.MaterialBindingAPI(bind_prim).ComputeBoundMaterial(
            UsdShade.Tokens.full)
        material_prim = material.GetPrim() if material else None
        gprim_values = material_api_values(gprim, self.time)
        if _has_api(gprim, schema.MATERIAL_API):  # every value comes from the gprim
            key = gprim_path
        elif gprim_values or _authored_spectra(gprim):
            # some values from the gprim, the rest from this binding
            key = str(bind_prim.GetPath())
        elif material_prim is not None:
            key = str(material_prim.GetPath())
        else:
            key = DEFAULT_MATERIAL_PATH
            self.unbound.append(gprim_path)
        if key in self.index:
            return self.index[key]

        values = {name: Sourced(value, key or gprim_path, name)
                  for name, value in schema.MATERIAL_FALLBACKS.items()}
        if material_prim is not None:
            values.update(preview_values(material, self.time, self.warn))
            values.update(material_api_values(material_prim, self.time))
        values.update(gprim_values)
        colour = values.pop(PREVIEW_COLOUR, None)
        validate.check_material(values)
        self._warn_lossless(values)
        scattering = str(values[schema.SCATTERING].value)
        spectral = surface_spectra(
            ([gprim] if key in (gprim_path, str(bind_prim.GetPath())) else [])
            + ([material_prim] if material_prim is not None and key != gprim_path else []),
            self.time,
            scattering, {"reflectance": float(values[schema.REFLECTANCE].value),
                         "specular": float(values[schema.SPECULAR_REFLECTANCE].value),
                         "transmittance": float(values[schema.TRANSMITTANCE].value)},
            colour.value if colour is not None else None)
        scalars = {f: spectral.pop(f) for f in ("reflectance", "specular_reflectance",
                                               "transmittance") if f in spectral}
        mat = Material(
            path=key,
            scattering=str(values[schema.SCATTERING].value),
            reflectance=float(values[schema.REFLECTANCE].value),
            specular_reflectance=float(values[schema.SPECULAR_REFLECTANCE].value),
            transmittance=float(values[schema.TRANSMITTANCE].value),
            ior=float(values[schema.IOR].value),
            roughness=float(values[schema.ROUGHNESS].value),
        )
        mat = dataclasses.replace(mat, **scalars, **spectral)
        self.index[key] = len(self.materials)
        self.materials.append(mat)
        return self.index[key]


    def _warn_lossless(self, values: dict) -> None:
        """Warn when a UsdPreviewSurface maps to a surface that absorbs nothing (a white
        diffuse, a white metal: a chrome reflector with a light output ratio of 1.000)."""
        kind = str(values[schema.SCATTERING].value)
        name = {"diffuse": schema.REFLECTANCE, "mirror": schema.SPECULAR_REFLECTANCE,
                "glossy": schema.SPECULAR_REFLECTANCE}.get(kind)
        if name is None:
            return
        v = values[name]
        if float(v.value) >= LOSSLESS and not str(v.prop).startswith("lumitrace:"):
            self.warn(f"{v.where}.{v.prop}: the UsdPreviewSurface maps to a {kind} surface "
                      f"of reflectance {float(v.value):.3f}, which absorbs no light; real "
                      f"ones do (polished aluminium about 0.9): author {name} "
                      "(LumitraceMaterialAPI) or a darker colour")


#: A PreviewSurface albedo from which the surface is taken for a lossless one (warned).
LOSSLESS = 0.99


def _authored_spectra(prim: Usd.Prim) -> bool:
    """Whether ``prim`` has a spectral material attribute of its own."""
    return any(prim.GetAttribute(n) and prim.GetAttribute(n).HasAuthoredValue()
               for n in schema.MATERIAL_COLOUR_ATTRIBUTES)


def _has_api(prim: Usd.Prim, name: str) -> bool:
    """Whether the API schema ``name`` is applied to ``prim``, also when USD does not know
    the schema (its plugin was registered too late): then ``apiSchemas`` still lists it."""
    return prim.HasAPI(name) or name in prim.GetPrimTypeInfo().GetAppliedAPISchemas()


def material_api_values(prim: Usd.Prim, time: Usd.TimeCode) -> dict[str, Sourced]:
    """lumitrace material attributes on ``prim``: all of them where LumitraceMaterialAPI is
    applied (schema fallbacks included), else only the authored ones."""
    applied = _has_api(prim, schema.MATERIAL_API)
    where = str(prim.GetPath())
    values = {}
    for name in schema.MATERIAL_ATTRIBUTES:
        attr = prim.GetAttribute(name)
        if not attr:
            continue
        if applied or attr.HasAuthoredValue():
            value = attr.Get(time)
            if value is None and applied:
                value = schema.MATERIAL_FALLBACKS[name]
            values[name] = Sourced(value, where, name)
    if applied:
        for name, fallback in schema.MATERIAL_FALLBACKS.items():
            values.setdefault(name, Sourced(fallback, where, name))
    return values


def preview_values(material: UsdShade.Material, time: Usd.TimeCode,
                   warn: Callable[[str], None]) -> dict[str, Sourced]:
    """Values from the material's UsdPreviewSurface, sourced to the shader's inputs."""
    shader, _, _ = material.ComputeSurfaceSource()
    if not shader or shader.GetShaderId() != "UsdPreviewSurface":
        return {}
    where = str(shader.GetPath())
    inputs = {}
    sources = {}
    for name, default in (("diffuseColor", (0.18, 0.18, 0.18)), ("metallic", 0.0),
                          ("roughness", 0.5), ("opacity", 1.0), ("ior", 1.5),
                          ("useSpecularWorkflow", 0), ("specularColor", (0.0, 0.0, 0.0))):
        value, source = _shader_input(shader, name, default, time, warn)
        inputs[name] = value
        sources[name] = source
    for name in ("metallic", "roughness", "opacity", "ior", "useSpecularWorkflow"):
        src_where, src_prop = sources[name]
        validate.check_finite(inputs[name], src_where, src_prop)
    for name in ("diffuseColor", "specularColor"):
        src_where, src_prop = sources[name]
        validate.check_finite_points(np.asarray(inputs[name], dtype=np.float64).reshape(1, 3),
                                     src_where, src_prop, what="colours")
    derived = preview_surface_values(
        diffuse_color=inputs["diffuseColor"], metallic=inputs["metallic"],
        roughness=inputs["roughness"], opacity=inputs["opacity"], ior=inputs["ior"],
        use_specular_workflow=int(inputs["useSpecularWorkflow"]),
        specular_color=inputs["specularColor"])
    origin = {schema.SCATTERING: "opacity" if inputs["opacity"] < 1.0 else "diffuseColor",
              schema.REFLECTANCE: "diffuseColor",
              schema.SPECULAR_REFLECTANCE: ("specularColor" if inputs["useSpecularWorkflow"]
                                            else "diffuseColor"),
              schema.ROUGHNESS: "roughness", schema.IOR: "ior",
              schema.TRANSMITTANCE: "opacity"}
    out = {name: Sourced(value, *sources[origin[name]]) if origin[name] in sources
           else Sourced(value, where, name)
           for name, value in derived.items()}
    albedo = origin[schema.SPECULAR_REFLECTANCE if schema.SPECULAR_REFLECTANCE in derived
                    else schema.REFLECTANCE]
    out[PREVIEW_COLOUR] = Sourced(inputs[albedo], *sources[albedo])
    return out


def _shader_input(shader: UsdShade.Shader, name: str, default, time: Usd.TimeCode,
                  warn: Callable[[str], None]):
    """Value of a shader input and where it comes from (connections followed to
    material interface inputs; a texture gives the default, with a warning)."""
    where = (str(shader.GetPath()), f"inputs:{name}")
    shader_input = shader.GetInput(name)
    if not shader_input:
        return default, where
    attrs = shader_input.GetValueProducingAttributes(False)
    if not attrs:
        return default, where
    attr = attrs[0]
    if UsdShade.Output.IsOutput(attr):
        warn(f"{where[0]}.{where[1]}: connected to a texture or node output: "
             f"using the UsdPreviewSurface default {default!r}")
        return default, where
    value = attr.Get(time)
    source = (str(attr.GetPrim().GetPath()), attr.GetName())
    if value is None:
        return default, source
    if isinstance(value, (bool, int, float)):
        return value, source
    try:
        return tuple(float(v) for v in value), source
    except TypeError:
        return value, source
