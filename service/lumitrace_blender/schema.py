"""The lumitrace schema as the add-on needs it: each attribute's USD type, API schema,
fallback and the range lumitrace validates, so that an ID property gets the right limits
and an export writes exactly what lumitrace reads.

Mirrors ``schemas/schema.usda`` (the project's tests compare the two); kept as data here
because Blender's own USD knows nothing of lumitrace's codeless schema.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

MATERIAL_API = "LumitraceMaterialAPI"
EMITTER_API = "LumitraceEmitterAPI"
LUMINAIRE_API = "LumitraceLuminaireAPI"
PROFILE_API = "LumitraceProfileAPI"
PREFIX = "lumitrace:"
RESULT_PREFIX = "lumitrace:result:"
SCATTERING_TOKENS = ("diffuse", "mirror", "glossy", "translucent", "dielectric", "absorber")
SYMMETRY_TOKENS = ("auto", "none", "rotational", "quadrant", "C0-C180", "C90-C270")
OPENING_SHAPES = ("measured", "rectangular", "round")
PROFILE_KINDS = ("revolve", "extrude")
#: The largest flux lumitrace takes for one light (lm).
MAX_LUMINOUS_FLUX = 1e24


@dataclass(frozen=True)
class Attribute:
    """One schema attribute: ``name`` (``lumitrace:...``), the ``api`` schema defining it,
    its Sdf value type name ``usd_type``, ``fallback`` (None: no fallback), the closed
    range ``low``..``high`` (None: unbounded), ``low_open`` (the low end excluded),
    ``tokens`` (allowed values of a token) and a one-line ``doc`` with its unit."""

    name: str
    api: str
    usd_type: str
    fallback: object = None
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    tokens: tuple[str, ...] = ()
    uniform: bool = False
    doc: str = ""

    @property
    def label(self) -> str:
        """The name without ``lumitrace:``, as the panels show it."""
        return self.name[len(PREFIX):]

    @property
    def is_array(self) -> bool:
        return self.usd_type.endswith("[]")

    def check(self, value) -> str | None:
        """Why ``value`` is not one lumitrace accepts for this attribute (None: it is)."""
        if self.usd_type in ("float", "double", "int"):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                return f"must be a number, got {value!r}"
            if self.usd_type == "int" and value != int(value):
                return f"must be a whole number, got {value!r}"
            if not math.isfinite(value):
                return f"must be finite, got {value!r}"
            if self.low is not None and (value <= self.low if self.low_open else
                                         value < self.low):
                return f"must be {'>' if self.low_open else '>='} {self.low:g}, got {value:g}"
            if self.high is not None and value > self.high:
                return f"must be <= {self.high:g}, got {value:g}"
        elif self.usd_type == "token":
            if value not in self.tokens:
                return f"must be one of {', '.join(self.tokens)}, got {value!r}"
        elif self.usd_type in ("string", "asset"):
            if not isinstance(value, str):
                return f"must be text, got {value!r}"
            if "\x00" in value:
                return "must not hold a NUL character"
        elif self.usd_type == "bool":
            if not isinstance(value, (bool, int)) or value not in (0, 1):
                return f"must be true or false, got {value!r}"
        elif self.usd_type == "float2[]":
            try:
                pairs = [(float(a), float(b)) for a, b in value]
            except (TypeError, ValueError):
                return "must be a list of pairs of numbers"
            if not all(math.isfinite(a) and math.isfinite(b) for a, b in pairs):
                return "must hold finite numbers"
            if self.api == PROFILE_API:  # (r, z) points; lumitrace checks the rest
                return None if len(pairs) >= 2 else "needs at least 2 points"
            if any(b < 0 for _, b in pairs):
                return "values must be >= 0"
            if any(b[0] <= a[0] for a, b in zip(pairs, pairs[1:])):
                return "wavelengths must increase"
        elif self.usd_type == "double3":
            try:
                numbers = [float(v) for v in value]
            except (TypeError, ValueError):
                return "must be three numbers"
            if len(numbers) != 3 or not all(math.isfinite(v) for v in numbers):
                return "must be three finite numbers"
            if self.low is not None and any(v < self.low for v in numbers):
                return f"each must be >= {self.low:g}"
        elif self.usd_type == "float[]":
            try:
                numbers = [float(v) for v in value]
            except (TypeError, ValueError):
                return "must be a list of numbers"
            if not all(math.isfinite(v) for v in numbers):
                return "must hold finite numbers"
        return None


def _m(name, usd_type, fallback=None, **kw) -> Attribute:
    return Attribute(PREFIX + name, MATERIAL_API, usd_type, fallback, **kw)


def _e(name, usd_type, fallback=None, **kw) -> Attribute:
    return Attribute(PREFIX + name, EMITTER_API, usd_type, fallback, **kw)


def _l(name, usd_type, fallback=None, **kw) -> Attribute:
    return Attribute(PREFIX + name, LUMINAIRE_API, usd_type, fallback, **kw)


def _p(name, usd_type, fallback=None, **kw) -> Attribute:
    return Attribute(PREFIX + "profile:" + name, PROFILE_API, usd_type, fallback, **kw)


#: Every attribute a user edits (the ``lumitrace:result:*`` ones are lumitrace's output).
ATTRIBUTES: tuple[Attribute, ...] = (
    _m("scattering", "token", "diffuse", tokens=SCATTERING_TOKENS, uniform=True,
       doc="scattering model: diffuse, mirror, glossy, translucent, dielectric, absorber"),
    _m("reflectance", "float", 0.8, low=0.0, high=1.0,
       doc="diffuse (Lambertian) reflectance, a fraction"),
    _m("specularReflectance", "float", 1.0, low=0.0, high=1.0,
       doc="mirror or glossy reflectance, a fraction"),
    _m("transmittance", "float", 0.0, low=0.0, high=1.0,
       doc="diffuse transmittance of a translucent material, a fraction"),
    _m("ior", "float", 1.5, low=0.0, low_open=True,
       doc="refractive index of a dielectric (> 0)"),
    _m("roughness", "float", 0.2, low=0.0, high=1.0,
       doc="GGX roughness of a glossy material (alpha = roughness^2)"),
    _m("reflectanceSpectrum", "float2[]",
       doc="spectral diffuse reflectance: (nm, fraction) pairs"),
    _m("specularSpectrum", "float2[]",
       doc="spectral mirror or glossy reflectance: (nm, fraction) pairs"),
    _m("transmittanceSpectrum", "float2[]",
       doc="spectral diffuse transmittance: (nm, fraction) pairs"),
    _m("abbeNumber", "float", 0.0, low=0.0,
       doc="Abbe number of a dielectric (0: no dispersion)"),
    _m("sellmeier", "float[]",
       doc="Sellmeier coefficients B1, B2, B3, C1, C2, C3 (C in square micrometres)"),
    _e("luminousFlux", "float", 0.0, low=0.0, high=MAX_LUMINOUS_FLUX, low_open=True,
       doc="luminous flux of the light (lm)"),
    _e("spectrum", "float2[]", doc="relative spectral power: (nm, power) pairs"),
    _e("illuminant", "string", "",
       doc="the light's spectrum by name (\"blackbody 2700\", D65, LED-B3, ...)"),
    _e("body", "bool", False, doc="the light's own surface is opaque geometry too"),
    _e("rayFile", "asset", doc="IES TM-25 ray file the light emits"),
    _l("manufacturer", "string", doc="manufacturer (IES [MANUFAC])"),
    _l("luminaireName", "string", doc="luminaire name (IES [LUMINAIRE])"),
    _l("catalogueNumber", "string", doc="catalogue number (IES [LUMCAT])"),
    _l("lampDescription", "string", doc="lamps or LED modules (IES [LAMP])"),
    _l("inputPower", "double", low=0.0, doc="electrical input power (W)"),
    _l("colourRenderingIndex", "double", high=100.0, doc="colour rendering index Ra"),
    _l("symmetry", "token", "auto", tokens=SYMMETRY_TOKENS, uniform=True,
       doc="declared symmetry of the distribution (auto: lumitrace shows it)"),
    _l("luminousOpeningShape", "token", "measured", tokens=OPENING_SHAPES, uniform=True,
       doc="luminous opening: measured, or declared rectangular or round"),
    _l("luminousOpening", "double3", (0.0, 0.0, 0.0), low=0.0,
       doc="declared opening: length (C0), width (C90), height, stage units"),
    _p("points", "float2[]", doc="the profile's (r, z) polyline, the mesh's local units"),
    _p("kind", "token", "revolve", tokens=PROFILE_KINDS, uniform=True,
       doc="revolve about the local up axis, or extrude across it"),
    _p("segments", "int", 64, low=1.0, high=4096.0,
       doc="faces around a revolve (3-4096) or along an extrusion (1-4096)"),
    _p("length", "float", 1.0, low=0.0, low_open=True,
       doc="length of an extrusion, the mesh's local units"),
)
BY_NAME = {a.name: a for a in ATTRIBUTES}
#: The attributes of each API schema, in the schema's order.
BY_API = {api: tuple(a for a in ATTRIBUTES if a.api == api)
          for api in (MATERIAL_API, EMITTER_API, LUMINAIRE_API, PROFILE_API)}


def is_result(name: str) -> bool:
    """A ``lumitrace:result:*`` attribute: written by lumitrace, read-only in Blender."""
    return name.startswith(RESULT_PREFIX)
