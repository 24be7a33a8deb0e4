"""The lumitrace codeless USD schema: registration with usd-core, names, allowed values.

The schema (``schemas/schema.usda``, generated into ``schemas/plugInfo.json`` and
``schemas/generatedSchema.usda``) defines four single-apply API schemas:

- ``LumitraceMaterialAPI`` on a UsdShade Material or a gprim: ``lumitrace:scattering``,
  ``lumitrace:reflectance``, ``lumitrace:specularReflectance``, ``lumitrace:transmittance``,
  ``lumitrace:ior``, ``lumitrace:roughness``, their spectra
  (``lumitrace:reflectanceSpectrum``, ``...specularSpectrum``, ``...transmittanceSpectrum``)
  and a dielectric's dispersion (``lumitrace:abbeNumber`` or ``lumitrace:sellmeier``);
- ``LumitraceEmitterAPI`` on a UsdLux light: ``lumitrace:luminousFlux`` (lm),
  ``lumitrace:body`` (the light's surface is geometry too), ``lumitrace:rayFile`` (a
  TM-25 ray file the light emits) and its colour, ``lumitrace:spectrum`` or
  ``lumitrace:illuminant``;
- ``LumitraceLuminaireAPI`` on the luminaire (default) prim: ``lumitrace:result:*``;
- ``LumitraceProfileAPI`` on a mesh: the profile it is made from
  (``lumitrace:profile:points``, ``:kind``, ``:segments``, ``:length``; see
  :mod:`lumitrace.stage.profile`).

Regenerate the generated files after editing ``schema.usda`` with::

    pip install jinja2
    python tools/generate_schema.py

USD does not enforce ``allowedTokens`` nor value ranges: the constants below are what the
stage reader validates against (:mod:`lumitrace.stage.validate`).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
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
PROFILE_API = "LumitraceProfileAPI"
API_SCHEMAS = (MATERIAL_API, EMITTER_API, LUMINAIRE_API, PROFILE_API)

# -- LumitraceMaterialAPI -------------------------------------------------------------
SCATTERING = "lumitrace:scattering"
REFLECTANCE = "lumitrace:reflectance"
SPECULAR_REFLECTANCE = "lumitrace:specularReflectance"
TRANSMITTANCE = "lumitrace:transmittance"
IOR = "lumitrace:ior"
ROUGHNESS = "lumitrace:roughness"
#: Spectral material attributes ((nm, value) pairs) and a dielectric's dispersion.
REFLECTANCE_SPECTRUM = "lumitrace:reflectanceSpectrum"
SPECULAR_SPECTRUM = "lumitrace:specularSpectrum"
TRANSMITTANCE_SPECTRUM = "lumitrace:transmittanceSpectrum"
ABBE_NUMBER = "lumitrace:abbeNumber"
SELLMEIER = "lumitrace:sellmeier"
#: The material attributes of colour (read by :mod:`lumitrace.stage.colour`).
MATERIAL_COLOUR_ATTRIBUTES = (REFLECTANCE_SPECTRUM, SPECULAR_SPECTRUM, TRANSMITTANCE_SPECTRUM,
                              ABBE_NUMBER, SELLMEIER)
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
RAY_FILE = "lumitrace:rayFile"
#: A light's colour: sampled relative power ((nm, power) pairs), or a named illuminant.
SPECTRUM = "lumitrace:spectrum"
ILLUMINANT = "lumitrace:illuminant"
BODY = "lumitrace:body"

# -- LumitraceProfileAPI --------------------------------------------------------------
#: A mesh's generating profile: (r, z) points, how it is made, segments, an extrusion's
#: length (local units).
PROFILE_POINTS = "lumitrace:profile:points"
PROFILE_KIND = "lumitrace:profile:kind"
PROFILE_SEGMENTS = "lumitrace:profile:segments"
PROFILE_LENGTH = "lumitrace:profile:length"
PROFILE_ATTRIBUTES = (PROFILE_POINTS, PROFILE_KIND, PROFILE_SEGMENTS, PROFILE_LENGTH)
#: Allowed values of ``lumitrace:profile:kind``.
PROFILE_KINDS = ("revolve", "extrude")
#: Schema fallbacks (mirrors ``schemas/schema.usda``).
PROFILE_FALLBACKS = {PROFILE_KIND: "revolve", PROFILE_SEGMENTS: 64, PROFILE_LENGTH: 1.0}

# -- LumitraceLuminaireAPI and the result record ---------------------------------------
#: The luminaire's own data, written into the photometric files: text attributes, and the
#: input power (W, at least 0) and colour rendering index (Ra, at most 100).
MANUFACTURER = "lumitrace:manufacturer"
LUMINAIRE_NAME = "lumitrace:luminaireName"
CATALOGUE_NUMBER = "lumitrace:catalogueNumber"
LAMP_DESCRIPTION = "lumitrace:lampDescription"
INPUT_POWER = "lumitrace:inputPower"
COLOUR_RENDERING_INDEX = "lumitrace:colourRenderingIndex"
LUMINAIRE_TEXT = (MANUFACTURER, LUMINAIRE_NAME, CATALOGUE_NUMBER, LAMP_DESCRIPTION)
#: A declared symmetry of the distribution ("auto": shown by lumitrace, see
#: :mod:`lumitrace.scene.symmetry`), and a declared luminous opening (shape, and size in
#: stage units: length along C0, width along C90, height).
SYMMETRY = "lumitrace:symmetry"
SYMMETRY_TOKENS = ("auto", "none", "rotational", "quadrant", "C0-C180", "C90-C270")
OPENING_SHAPE = "lumitrace:luminousOpeningShape"
OPENING_SHAPES = ("measured", "rectangular", "round")
OPENING_SIZE = "lumitrace:luminousOpening"
RESULT_PREFIX = "lumitrace:result:"


@dataclass(frozen=True)
class ResultField:
    """One figure of a traced result, declared once for every place it is written.

    ``key`` names it in the result record, the ``--json`` summary and the service's JSON
    (snake_case, unit in the name where it helps); ``attribute`` is its result-layer
    attribute after ``lumitrace:result:`` (None: not in the layer) with Sdf value ``kind``
    (asset, int64, int, double, bool, string; vector and list are JSON only); ``exr`` is
    its key in the EXR header's JSON metadata (None: not there); ``group`` nests it in the
    JSON summary (``outputs`` for file paths, ``photometry`` for the photometric figures,
    ``colour`` for the colour figures, which a stage without colour does not have).
    """

    key: str
    kind: str
    unit: str = ""
    attribute: str | None = None
    exr: str | None = None
    group: str | None = None
    doc: str = ""


def _f(key, kind, unit="", attribute=None, exr=None, group=None, doc=""):
    return ResultField(key, kind, unit, attribute, exr, group, doc)


#: The result record's fields, in the order they are written.
RESULT_FIELDS: tuple[ResultField, ...] = (
    _f("stage", "string", exr="stage", doc="stage file the result belongs to"),
    _f("luminaire", "string", exr="luminaire", doc="luminaire prim path"),
    _f("intensity_map", "asset", attribute="intensityMap", group="outputs",
       doc="cube-map EXR of the intensity"),
    _f("latlong_map", "asset", attribute="latlongMap", group="outputs",
       doc="lat-long environment texture of the intensity (tiled, mip-mapped EXR)"),
    _f("ies", "asset", attribute="iesFile", group="outputs", doc="IES LM-63-2019 file"),
    _f("ldt", "asset", attribute="ldtFile", group="outputs", doc="EULUMDAT file"),
    _f("polar_diagram", "asset", attribute="polarDiagram", group="outputs",
       doc="polar light distribution curve (PNG)"),
    _f("photometric_solid", "asset", attribute="photometricSolid", group="outputs",
       doc="photometric solid around the luminaire (PNG)"),
    _f("photometry_data", "asset", attribute="photometryData", group="outputs",
       doc="the photometric grid and figures with their standard errors (JSON)"),
    _f("result_layer", "asset", group="outputs", doc="the result layer"),
    _f("photons", "int64", "photons", "photons", "photons", doc="photons traced"),
    _f("iterations", "int", "", "iterations", "iterations", doc="progressive iterations"),
    _f("seconds", "double", "s", "elapsedSeconds", "elapsedSeconds",
       doc="tracing time"),
    _f("emitted_lm", "double", "lm", exr="emittedFlux", doc="flux of the emitters"),
    _f("escaped_lm", "double", "lm", "luminousFlux", "luminousFlux",
       doc="flux leaving the luminaire"),
    _f("absorbed_lm", "double", "lm", exr="absorbedFlux", doc="flux absorbed by its parts"),
    _f("cut_lm", "double", "lm", exr="cutFlux", doc="flux of photons cut by the depth limit"),
    _f("light_output_ratio", "double", "", "lightOutputRatio", "lightOutputRatio",
       doc="escaped / emitted flux"),
    _f("relative_error", "double", "", "relativeError", "relativeError",
       doc="estimated relative RMS error of the written map over the sphere"),
    _f("relative_error_bound", "double", "", "relativeErrorBound", "relativeErrorBound",
       doc="upper estimate of relative_error (its bias term's uncertainty added): what "
           "converged is judged on"),
    _f("raw_relative_error", "double", "", exr="rawRelativeError",
       doc="estimated relative RMS error of the raw map"),
    _f("filtered_relative_error", "double", "", exr="filteredRelativeError",
       doc="estimated relative RMS error of the filtered map"),
    _f("converged", "bool", "", "converged", "converged",
       doc="the judged error (target_of) at or below the target"),
    _f("target_error", "double", "", exr="targetError", doc="target error (null: the default)"),
    _f("target_of", "string", "", "targetOf", "targetOf",
       doc="what the target is judged on: files (the IES/LDT grid's RMS bound and worst lit "
           "value) or map (the written map's error bound)"),
    _f("judged_error", "double", "", "judgedError", "judgedError",
       doc="the error compared with the target: files, the larger of the RMS bound and a "
           "third of the worst lit value's; map, relative_error_bound"),
    _f("threshold", "double", "photons", "threshold", "threshold",
       doc="pull-push filter threshold"),
    _f("resolution", "int", "texels", "resolution", "resolution", doc="cube-map face size"),
    _f("seed", "int", "", "seed", "seed", doc="random seed"),
    _f("input_hash", "string", "", "inputHash", "inputHash",
       doc="hash of the scene content and the settings that shape the map"),
    _f("scene_hash", "string", "", "sceneHash", "sceneHash",
       doc="hash of the scene content alone: results whose hash differs are stale"),
    _f("photons_per_second", "double", "1/s", doc="photons traced per second"),
    _f("segments_per_second", "double", "1/s", doc="path segments traced per second"),
    _f("batches_redone", "int", "", doc="batches sent again after a Dask worker was lost"),
    _f("light_output_ratio_error", "double", "", exr="lightOutputRatioError",
       doc="standard error of the light output ratio"),
    _f("luminous_flux", "double", "lm", group="photometry",
       doc="flux of the photometric files (every escaping photon)"),
    _f("luminous_flux_error", "double", "lm", "luminousFluxError", group="photometry",
       doc="standard error of the luminous flux"),
    _f("lamp_flux", "double", "lm", group="photometry", doc="emitters' flux"),
    _f("downward_flux_fraction", "double", "", "downwardFluxFraction", group="photometry",
       doc="share of the luminaire's flux below the horizon"),
    _f("downward_flux_fraction_error", "double", "", group="photometry",
       doc="standard error of the downward flux fraction"),
    _f("upward_flux_fraction", "double", "", group="photometry",
       doc="share of the luminaire's flux above the horizon"),
    _f("peak_intensity", "double", "cd", "peakIntensity", group="photometry",
       doc="intensity at the top of the distribution (a local fit located by one half "
           "of the photons, measured by the other: no maximum bias, no cell-mean bias)"),
    _f("peak_intensity_error", "double", "cd", "peakIntensityError", group="photometry",
       doc="standard error of the peak intensity"),
    _f("peak_c", "double", "deg", group="photometry", doc="C angle of the peak"),
    _f("peak_gamma", "double", "deg", group="photometry", doc="gamma angle of the peak"),
    _f("peak_direction", "vector", "", group="photometry",
       doc="direction of the peak, world axes"),
    _f("beam_angle_c0_c180", "double", "deg", "beamAngleC0", group="photometry",
       doc="beam (50%) angle in the C0-C180 plane"),
    _f("beam_angle_c0_c180_error", "double", "deg", group="photometry",
       doc="its standard error"),
    _f("beam_angle_c90_c270", "double", "deg", "beamAngleC90", group="photometry",
       doc="beam (50%) angle in the C90-C270 plane"),
    _f("beam_angle_c90_c270_error", "double", "deg", group="photometry",
       doc="its standard error"),
    _f("field_angle_c0_c180", "double", "deg", "fieldAngleC0", group="photometry",
       doc="field (10%) angle in the C0-C180 plane"),
    _f("field_angle_c0_c180_error", "double", "deg", group="photometry",
       doc="its standard error"),
    _f("field_angle_c90_c270", "double", "deg", "fieldAngleC90", group="photometry",
       doc="field (10%) angle in the C90-C270 plane"),
    _f("field_angle_c90_c270_error", "double", "deg", group="photometry",
       doc="its standard error"),
    _f("beam_crossings_c0_c180", "list", "deg", group="photometry",
       doc="every crossing of the beam's 50% level in the C0-C180 plane, signed from "
           "nadir (negative toward C180): more than two where the profile has a shoulder"),
    _f("beam_crossings_c90_c270", "list", "deg", group="photometry",
       doc="every crossing of the beam's 50% level in the C90-C270 plane"),
    _f("spread_notes", "table", "", group="photometry",
       doc="why a beam or field angle is undefined, by its key (absent: all defined)"),
    _f("cie_flux_code", "string", "", "cieFluxCode", group="photometry",
       doc="CIE flux code N1 N2 N3 N4 N5"),
    _f("cie_flux_code_values", "list", "%", group="photometry",
       doc="N1..N5 unrounded"),
    _f("cie_flux_code_errors", "list", "%", group="photometry",
       doc="standard errors of N1..N5"),
    _f("zonal_flux", "table", "lm", group="photometry",
       doc="flux per 10 deg gamma zone from nadir: [from deg, to deg, lm, standard error]"),
    _f("photometry_error", "double", "", "photometryError", group="photometry",
       doc="relative RMS standard error of the photometric grid as a whole"),
    _f("photometry_worst_error", "double", "", group="photometry",
       doc="largest relative standard error of a lit file value (a tenth of the largest "
           "or more), poles included"),
    _f("photometry_worst_at", "list", "deg", group="photometry",
       doc="C and gamma of that value"),
    _f("symmetry", "string", "", "symmetry", group="photometry",
       doc="symmetry the files are averaged over: none, rotational, quadrant, C0-C180 or "
           "C90-C270"),
    _f("symmetry_source", "string", "", "symmetrySource", group="photometry",
       doc="why that symmetry: declared (lumitrace:symmetry on the stage), geometry (the "
           "parts, materials and emitters map onto themselves), measured (the counts' "
           "departure from it within 1% RMS at its upper bound) or none (none shown)"),
    _f("luminous_opening", "vector", "m", group="photometry",
       doc="luminous length (C0), width (C90) and height of the opening"),
    _f("colour_data", "asset", attribute="colourData", group="outputs",
       doc="colour over angle: X, Y, Z, u'v', CCT and Duv per C-gamma cell (JSON)"),
    _f("colour_diagram", "asset", attribute="colourDiagram", group="outputs",
       doc="chromaticity over gamma and on the CIE 1976 diagram (PNG)"),
    _f("datasheet_html", "asset", attribute="datasheetHtml", group="outputs",
       doc="the datasheet, one HTML page (written with --deliverables)"),
    _f("datasheet_pdf", "asset", attribute="datasheetPdf", group="outputs",
       doc="the datasheet, one or two A4 pages (PDF, written with --deliverables)"),
    _f("gldf", "asset", attribute="gldfFile", group="outputs",
       doc="GLDF container (ISO 7127) with L3D geometry (written with --deliverables)"),
    _f("cct_K", "double", "K", "cct", "cct", group="colour",
       doc="correlated colour temperature of all the light (Ohno 2013)"),
    _f("duv", "double", "", "duv", "duv", group="colour",
       doc="Duv of all the light"),
    _f("chromaticity_uv", "vector", "", group="colour",
       doc="CIE 1976 u'v' of all the light"),
    _f("colour_uniformity_duv", "double", "", "colourUniformity", "colourUniformity",
       group="colour", doc="largest Delta u'v' of a beam direction from the beam's mean"),
    _f("colour_uniformity_noise", "double", "", group="colour",
       doc="RMS standard error of a beam direction's u'v' (the uniformity's noise)"),
    # -- application figures (photometry/tables.py): UGR, luminance, BUG, illuminance ----
    _f("ugr_table", "table", "UGR", group="photometry",
       doc="CIE 117 / CIE 190 UGR table: 19 rooms (x, y in H) by 5 reflectances, crosswise "
           "and endwise, spacing 0.25 H, with standard errors"),
    _f("ugr_4h8h_70_50_20", "double", "UGR", "ugr4H8H", group="photometry",
       doc="catalogue UGR: room 4H x 8H, reflectances 70/50/20, crosswise"),
    _f("ugr_4h8h_70_50_20_error", "double", "UGR", "ugr4H8HError", group="photometry",
       doc="its standard error"),
    _f("ugr_4h8h_70_50_20_endwise", "double", "UGR", group="photometry",
       doc="catalogue UGR viewed endwise"),
    _f("ugr_4h8h_70_50_20_endwise_error", "double", "UGR", group="photometry",
       doc="its standard error"),
    _f("luminance_table", "table", "cd/m2", group="photometry",
       doc="luminance (intensity over projected luminous area) at C every 15 deg, gamma "
           "45 to 85 deg, with standard errors"),
    _f("luminance_screen_max", "double", "cd/m2", "screenLuminanceMax", group="photometry",
       doc="largest luminance at gamma 65 to 85 deg, all C (EN 12464-1 screen work)"),
    _f("luminance_screen_max_error", "double", "cd/m2", group="photometry",
       doc="its standard error"),
    _f("luminance_screen_max_c", "double", "deg", group="photometry", doc="its C angle"),
    _f("luminance_screen_max_gamma", "double", "deg", group="photometry",
       doc="its gamma angle"),
    _f("luminance_screen_limits", "table", "cd/m2", group="photometry",
       doc="EN 12464-1 limits for screens above and at most 200 cd/m2, and whether met"),
    _f("bug_rating", "string", "", "bugRating", group="photometry",
       doc="IES TM-15-11 BUG rating, from zone lumens of exact photon counts"),
    _f("bug_rating_range", "string", "", group="photometry",
       doc="the ratings with every zone two standard errors lower and higher"),
    _f("bug_zone_lumens", "table", "lm", group="photometry",
       doc="TM-15 zone lumens FL .. BVH, UL, UH"),
    _f("bug_zone_lumens_error", "table", "lm", group="photometry",
       doc="their standard errors"),
    _f("cone_diagram", "table", "", group="photometry",
       doc="centre illuminance (lx) and beam diameters (m) at mounting distances, with "
           "errors (inverse-square far field)"),
    _f("isolux", "table", "lx", group="photometry",
       doc="illuminance and its error on a plane 1 m below (x along C0, y along C90, m; "
           "far field)"),
)
#: Result-layer attribute (after ``lumitrace:result:``) -> Sdf value kind.
RESULT_KINDS: dict[str, str] = {f.attribute: f.kind for f in RESULT_FIELDS if f.attribute}
#: Full result attribute name -> Sdf value kind, as in ``schemas/schema.usda``.
RESULT_ATTRIBUTES = {RESULT_PREFIX + k: v for k, v in RESULT_KINDS.items()}

_registered = False
_building = False  # USD's schema registry built, or being built
#: The environment variable USD's plugin registry takes plugin folders from.
PLUGIN_PATH_VARIABLE = "PXR_PLUGINPATH_NAME"


def register_schema() -> None:
    """Register the schema plugin by absolute path, once, before any stage is composed.

    Importing :mod:`lumitrace` calls this. USD ignores a registration made after its schema
    registry was first loaded: if that happened (pxr used before ``import lumitrace``), a
    warning says so and the API schemas stay unknown for this process.

    Where no pxr module was loaded before (a command, a fresh interpreter), the schema's
    folder is put first on ``PXR_PLUGINPATH_NAME``, which USD's plugin registry reads when
    it is made: USD is not loaded for it (0.1 s), and child processes inherit it. Where pxr
    was loaded but not its Usd, the folder is registered at once and USD's schema registry
    (20 ms) built on another thread while the rest of lumitrace loads, and checked there;
    where Usd was (a DCC's interpreter, a script that used pxr first), it is built and
    checked here.
    """
    global _registered, _building
    if _registered:
        return
    if not (SCHEMA_DIR / "plugInfo.json").exists():
        warnings.warn(f"lumitrace USD schema not found in {SCHEMA_DIR}: the lumitrace API "
                      "schemas are unknown to USD (attribute values are still read)",
                      RuntimeWarning, stacklevel=2)
        return
    import os
    import sys

    if not any(name == "pxr" or name.startswith("pxr.") for name in sys.modules):
        # USD not loaded yet: its plugin registry, made when USD first needs it, reads
        # the plugin path from the environment; USD then loads only when a stage is read
        # (a trace of a kept scene never loads it)
        paths = os.environ.get(PLUGIN_PATH_VARIABLE, "").split(os.pathsep)
        if str(SCHEMA_DIR) not in paths:
            os.environ[PLUGIN_PATH_VARIABLE] = os.pathsep.join(
                [str(SCHEMA_DIR), *(p for p in paths if p)])
        _registered = True
        return
    maybe_late = "pxr.Usd" in sys.modules
    from pxr import Plug, Usd  # noqa: F401  (loaded here, not first on the thread)

    Plug.Registry().RegisterPlugins(str(SCHEMA_DIR))
    _registered = True
    if maybe_late:
        _building = True  # built here: never again on a thread (nor warned twice)
        _check_registered(stacklevel=3)
    else:
        build_registry_soon()


def build_registry_soon() -> None:
    """Have USD's schema registry (20 ms, which the first stage would build) built on a
    thread of its own, once, while the caller goes on loading (USD builds it without
    holding the interpreter); checked there. For a process that registered the schema
    through the plugin path and has just loaded pxr's Usd."""
    global _building
    if _building or not _registered:
        return
    _building = True
    _build_in_background(_check_registered)


def _check_registered(stacklevel: int = 1) -> None:
    """Warn where USD's schema registry (built by this call if it was not) lacks the
    lumitrace API schemas: it was loaded before they were registered."""
    if not is_registered():
        warnings.warn("the lumitrace USD schema was registered after USD's schema registry "
                      "was loaded: import lumitrace before composing any stage",
                      RuntimeWarning, stacklevel=stacklevel)


def _build_in_background(build) -> None:
    """Call ``build`` on a thread of its own, joined before this process forks or exits
    (a child must not inherit USD's locks mid-build, nor exit run under it)."""
    import atexit
    import os
    import threading

    thread = threading.Thread(target=build, name="lumitrace-usd-schemas", daemon=True)
    thread.start()
    atexit.register(thread.join)
    if hasattr(os, "register_at_fork"):
        os.register_at_fork(before=thread.join)


def is_registered() -> bool:
    """Whether USD's schema registry knows all the lumitrace API schemas."""
    from pxr import Usd

    registry = Usd.SchemaRegistry()
    return all(registry.FindAppliedAPIPrimDefinition(name) is not None
               for name in API_SCHEMAS)
