"""The lumitrace codeless USD schema: registration with usd-core, names, allowed values.

The schema (``schemas/schema.usda``, generated into ``schemas/plugInfo.json`` and
``schemas/generatedSchema.usda``) defines three single-apply API schemas:

- ``LumitraceMaterialAPI`` on a UsdShade Material or a gprim: ``lumitrace:scattering``,
  ``lumitrace:reflectance``, ``lumitrace:specularReflectance``, ``lumitrace:transmittance``,
  ``lumitrace:ior``, ``lumitrace:roughness``;
- ``LumitraceEmitterAPI`` on a UsdLux light: ``lumitrace:luminousFlux`` (lm);
- ``LumitraceLuminaireAPI`` on the luminaire (default) prim: ``lumitrace:result:*``.

Regenerate the generated files after editing ``schema.usda`` with::

    pip install jinja2
    python tools/generate_schema.py

USD does not enforce ``allowedTokens`` nor value ranges: the constants below are what the
stage reader validates against (:mod:`lumitrace.stage.validate`).
"""
from __future__ import annotations

import warnings
from pathlib import Path

from .scene import SCATTERING_MODELS

#: Folder holding plugInfo.json and generatedSchema.usda (``schemas/`` of the source tree).
def _schema_dir() -> Path:
    """``schemas/`` of the source tree, or its copy inside an installed (wheel) package."""
    here = Path(__file__).resolve().parent
    packaged = here / "schemas"
    return packaged if (packaged / "plugInfo.json").exists() else here.parents[1] / "schemas"


SCHEMA_DIR = _schema_dir()

#: API schema type names, as written in ``schemas/schema.usda``.
MATERIAL_API = "LumitraceMaterialAPI"
EMITTER_API = "LumitraceEmitterAPI"
LUMINAIRE_API = "LumitraceLuminaireAPI"
API_SCHEMAS = (MATERIAL_API, EMITTER_API, LUMINAIRE_API)

# -- LumitraceMaterialAPI -------------------------------------------------------------
SCATTERING = "lumitrace:scattering"
REFLECTANCE = "lumitrace:reflectance"
SPECULAR_REFLECTANCE = "lumitrace:specularReflectance"
TRANSMITTANCE = "lumitrace:transmittance"
IOR = "lumitrace:ior"
ROUGHNESS = "lumitrace:roughness"
#: Material attribute name -> :class:`lumitrace.scene.Material` field name.
MATERIAL_ATTRIBUTES = {
    SCATTERING: "scattering",
    REFLECTANCE: "reflectance",
    SPECULAR_REFLECTANCE: "specular_reflectance",
    TRANSMITTANCE: "transmittance",
    IOR: "ior",
    ROUGHNESS: "roughness",
}
#: Allowed values of ``lumitrace:scattering`` (same order as the scene's integer codes).
SCATTERING_TOKENS: tuple[str, ...] = SCATTERING_MODELS
#: Schema fallbacks of the material attributes (mirrors ``schemas/schema.usda``).
MATERIAL_FALLBACKS = {
    SCATTERING: "diffuse",
    REFLECTANCE: 0.8,
    SPECULAR_REFLECTANCE: 1.0,
    TRANSMITTANCE: 0.0,
    IOR: 1.5,
    ROUGHNESS: 0.2,
}
#: Closed ranges ``(low, high)`` of the fractional material attributes.
UNIT_INTERVAL = (0.0, 1.0)
MATERIAL_RANGES = {
    REFLECTANCE: UNIT_INTERVAL,
    SPECULAR_REFLECTANCE: UNIT_INTERVAL,
    TRANSMITTANCE: UNIT_INTERVAL,
    ROUGHNESS: UNIT_INTERVAL,
}
#: ``lumitrace:ior`` must be finite and strictly greater than this.
IOR_EXCLUSIVE_MIN = 0.0

# -- LumitraceEmitterAPI --------------------------------------------------------------
#: Luminous flux in lm; only an authored value counts, and it must be finite and > 0.
LUMINOUS_FLUX = "lumitrace:luminousFlux"

# -- LumitraceLuminaireAPI ------------------------------------------------------------
RESULT_PREFIX = "lumitrace:result:"
#: Result attribute name -> Sdf value type name, as in ``schemas/schema.usda``.
#: The luminaire API's result attributes: name after ``lumitrace:result:`` -> value kind.
RESULT_FIELDS = {
    "intensityMap": "asset",
    "iesFile": "asset",
    "ldtFile": "asset",
    "photons": "int64",
    "iterations": "int",
    "elapsedSeconds": "double",
    "relativeError": "double",
    "luminousFlux": "double",
    "lightOutputRatio": "double",
    "threshold": "double",
    "resolution": "int",
    "seed": "int",
    "converged": "bool",
    "inputHash": "string",
    "downwardFluxFraction": "double",
    "peakIntensity": "double",
    "beamAngleC0": "double",
    "beamAngleC90": "double",
    "fieldAngleC0": "double",
    "fieldAngleC90": "double",
    "cieFluxCode": "string",
    "polarDiagram": "asset",
    "photometricSolid": "asset",
}
RESULT_ATTRIBUTES = {RESULT_PREFIX + k: v for k, v in RESULT_FIELDS.items()}

_registered = False


def register_schema() -> None:
    """Register the schema plugin by absolute path, once, before any stage is composed.

    Importing :mod:`lumitrace` calls this. USD ignores a registration made after its schema
    registry was first loaded: if that happened (pxr used before ``import lumitrace``), a
    warning says so and the API schemas stay unknown for this process.
    """
    global _registered
    if _registered:
        return
    if not (SCHEMA_DIR / "plugInfo.json").exists():
        warnings.warn(f"lumitrace USD schema not found in {SCHEMA_DIR}: the lumitrace API "
                      "schemas are unknown to USD (attribute values are still read)",
                      RuntimeWarning, stacklevel=2)
        return
    from pxr import Plug

    Plug.Registry().RegisterPlugins(str(SCHEMA_DIR))
    _registered = True
    if not is_registered():
        warnings.warn("the lumitrace USD schema was registered after USD's schema registry "
                      "was loaded: import lumitrace before composing any stage",
                      RuntimeWarning, stacklevel=2)


def is_registered() -> bool:
    """Whether USD's schema registry knows all three lumitrace API schemas."""
    from pxr import Usd

    registry = Usd.SchemaRegistry()
    return all(registry.FindAppliedAPIPrimDefinition(name) is not None
               for name in API_SCHEMAS)
