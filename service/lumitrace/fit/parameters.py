"""What a fit varies: parameters named on the command line and checked against the stage.

A ``--vary`` argument names one of:

- a numeric attribute, ``/Luminaire/Materials/Mirror.lumitrace:specularReflectance``;
- a component of a vector or array attribute by index,
  ``/Luminaire/Reflector.xformOp:translate[2]``,
  ``/Luminaire/Reflector.lumitrace:profile:points[3][0]`` (``[*]`` names every element,
  ``[A:B]`` elements A to B - 1: ``points[1:5][0]`` is one parameter per point);
- a variant set, ``/Luminaire{finish}`` (every variant) or ``/Luminaire{finish}=white,black``
  (a discrete parameter).

A numeric one takes its range after ``=``: ``LO:HI``, or ``+-D`` around the stage's value;
without one it takes the schema's (``[0, 1]`` for reflectances), and where the schema has
none the argument is refused. Whole-number attributes are discrete. Every problem (no such
prim or attribute, not a number, an index out of range, an empty range, an attribute that
is animated or not in the prim's transform order) is a :class:`FitError` naming the
argument, before anything is traced.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np
from pxr import Sdf, Usd, UsdGeom

from ..errors import LumitraceError
from ..schema import MATERIAL_RANGES, PROFILE_ATTRIBUTES, PROFILE_KIND, PROFILE_POINTS


class FitError(LumitraceError):
    """A fit's input is wrong: a parameter, a target, an objective (exit status 2)."""


#: Sdf scalar type names whose values are numbers or vectors of them.
_INTEGER = re.compile(r"^(int|uint|int64|uint64|uchar|int[234])$")
_REAL = re.compile(r"^(float|double|half|timecode|(float|double|half)[234]|"
                   r"(point|normal|vector)3[fdh]|color[34][fdh]|texCoord[23][fdh]|quat[fdh])$")
#: Attributes a fit refuses to vary: lumitrace's results, and the profile's own layout
#: (its kind and segments change the mesh's topology, not a shape).
_REFUSED = ("lumitrace:result:",)

_SPEC = re.compile(r"^(?P<path>/[^.{}=\s]*?)(?:\.(?P<prop>[^\[\]={}\s]+)(?P<index>(?:\[[^\]]*\])*)"
                   r"|\{(?P<set>[^{}=\s]+)\})(?:=(?P<range>.*))?$")


@dataclass(frozen=True)
class Parameter:
    """One value a fit varies. ``name`` is its spelling (the ``--vary`` argument, ``[*]``
    expanded, without its range); ``path`` the prim; ``prop`` the attribute (None for a
    variant set, ``variant_set`` then names it); ``index`` the element and component
    within the attribute's value. Continuous parameters lie in [``lo``, ``hi``]; discrete
    ones take one of ``choices`` (numbers or variant names). ``start`` is the stage's
    value."""

    name: str
    path: str
    prop: str | None
    index: tuple[int, ...] = ()
    lo: float = 0.0
    hi: float = 1.0
    start: float | str = 0.0
    choices: tuple = ()
    variant_set: str | None = None
    type_name: str = ""
    #: the stage's value lay outside the range given: the search starts at its edge
    clipped: bool = False
    schema_range: tuple[float, float] | None = field(default=None, compare=False)

    @property
    def discrete(self) -> bool:
        return bool(self.choices)

    @property
    def attribute(self) -> tuple[str, str | None]:
        """(prim path, attribute or ``{set}``): parameters of one attribute are authored
        together."""
        return self.path, self.prop if self.prop is not None else f"{{{self.variant_set}}}"

    @property
    def profile(self) -> bool:
        """Whether it changes a mesh's profile (and so its points)."""
        return self.prop in PROFILE_ATTRIBUTES

    # -- the search's coordinates -------------------------------------------------------

    def to_unit(self, value) -> float:
        """The search coordinate of ``value``: [0, 1] over the range, or a choice's index."""
        if self.discrete:
            return float(self.choices.index(value))
        return (float(value) - self.lo) / (self.hi - self.lo)

    def from_unit(self, x: float):
        """The value at search coordinate ``x`` (clipped into the range; a discrete one
        rounded to its nearest choice)."""
        if self.discrete:
            return self.choices[int(np.clip(round(float(x)), 0, len(self.choices) - 1))]
        return self.lo + float(np.clip(x, 0.0, 1.0)) * (self.hi - self.lo)

    @property
    def unit_bounds(self) -> tuple[float, float]:
        """Bounds of the search coordinate."""
        return (-0.5, len(self.choices) - 0.5) if self.discrete else (0.0, 1.0)

    def at_edge(self, value, share: float = 0.01) -> str | None:
        """``"low"`` or ``"high"`` where ``value`` lies within ``share`` of the range of an
        edge (the best may want to go further), else None."""
        if self.discrete:
            return None
        t = self.to_unit(value)
        return "low" if t <= share else "high" if t >= 1.0 - share else None

    def as_dict(self) -> dict:
        out = {"name": self.name, "path": self.path, "property": self.prop,
               "index": list(self.index), "start": self.start}
        if self.discrete:
            out["choices"] = list(self.choices)
            if self.variant_set:
                out["variant_set"] = self.variant_set
        else:
            out["range"] = [self.lo, self.hi]
        return out


def parse(text: str) -> dict:
    """The parts of one ``--vary`` argument (path, prop, index list or ``*``, set, range
    text), or a :class:`FitError` naming it."""
    m = _SPEC.match(text.strip())
    if not m:
        raise FitError("expected PATH.PROPERTY[=LO:HI], PATH.PROPERTY[i][=LO:HI] or "
                       "PATH{VARIANTSET}[=A,B]", f"--vary {text}")
    path = m.group("path")
    if not Sdf.Path.IsValidPathString(path) or not Sdf.Path(path).IsPrimPath():
        raise FitError(f"{path!r} is not a prim path", f"--vary {text}")
    index = []
    for item in re.findall(r"\[([^\]]*)\]", m.group("index") or ""):
        item = item.strip()
        if item == "*":
            index.append("*")
        elif re.fullmatch(r"\d+", item):
            index.append(int(item))
        elif re.fullmatch(r"\d*:\d*", item):
            a, b = item.split(":")
            index.append(slice(int(a) if a else None, int(b) if b else None))
        else:
            raise FitError(f"an index is a whole number, A:B or *, got [{item}]",
                           f"--vary {text}")
    return {"path": path, "prop": m.group("prop"), "index": index, "set": m.group("set"),
            "range": m.group("range")}


def _range(text: str, value: float, where: str) -> tuple[float, float]:
    """``LO:HI`` or ``+-D`` (around ``value``) as (lo, hi)."""
    t = text.strip().replace("±", "+-")
    try:
        if t.startswith("+-"):
            d = float(t[2:])
            if not (math.isfinite(d) and d > 0):
                raise FitError(f"the range's half-width must be a finite number > 0, got "
                               f"{t[2:]!r}", where)
            return value - d, value + d
        lo_text, hi_text = t.split(":")
        lo, hi = float(lo_text), float(hi_text)
    except ValueError:
        raise FitError(f"a range is LO:HI or +-D, got {text!r}", where) from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise FitError(f"the range must be finite, got {text!r}", where)
    if not lo < hi:
        raise FitError(f"the range {lo:g}:{hi:g} is empty (LO must be below HI)", where)
    return lo, hi


def _element(value, index: list, type_name: Sdf.ValueTypeName, where: str) -> list[tuple]:
    """The index tuples ``index`` (``*`` expanded) names in an attribute's ``value``, each
    reaching a number; a :class:`FitError` for a wrong depth or an index out of range."""
    array = np.asarray(value, dtype=np.float64) if value is not None else None
    if array is None:
        raise FitError("has no value to start from (author one on the stage)", where)
    if len(index) != array.ndim:
        what = {0: "a number", 1: "a vector or an array of numbers",
                2: "an array of vectors"}.get(array.ndim, "an array")
        want = "no index" if array.ndim == 0 else " ".join(["[i]"] * array.ndim)
        raise FitError(f"is {what} ({type_name}): name one number with {want}", where)
    out = [()]
    for depth, i in enumerate(index):
        size = array.shape[depth]
        what = "elements" if depth == 0 else "components"
        if isinstance(i, slice):
            picks = range(size)[i]
            if not picks or (i.stop is not None and i.stop > size):
                raise FitError(f"[{i.start or ''}:{i.stop or ''}] is out of range: it has "
                               f"{size} {what}", where)
        else:
            picks = range(size) if i == "*" else [i]
        if not isinstance(i, slice) and i != "*" and not 0 <= i < size:
            raise FitError(f"index {i} is out of range: it has {size} {what}", where)
        out = [t + (k,) for t in out for k in picks]
    return out


def _spelling(text: str, index: tuple[int, ...]) -> str:
    """The argument without its range, each ``[*]``, ``[A:B]`` and ``[i]`` replaced by
    the element's indices in turn."""
    base = text.split("=", 1)[0].strip()
    it = iter(index)
    return re.sub(r"\[[^\]]*\]", lambda _: f"[{next(it)}]", base)


def resolve(stage: Usd.Stage, texts: list[str]) -> list[Parameter]:
    """The parameters ``texts`` (``--vary`` arguments) name on ``stage``, checked."""
    out: list[Parameter] = []
    seen: dict[tuple, str] = {}
    for text in texts:
        where = f"--vary {text}"
        spec = parse(text)
        prim = stage.GetPrimAtPath(spec["path"])
        if not prim or not prim.IsActive():
            raise FitError(f"no active prim at {spec['path']} in the stage", where)
        params = _variant(prim, spec, text, where) if spec["set"] else \
            _numeric(prim, spec, text, where)
        for p in params:
            key = (p.path, p.prop, p.variant_set, p.index)
            if key in seen:
                raise FitError(f"{p.name} is already varied (by --vary {seen[key]})", where)
            seen[key] = text
        out.extend(params)
    if not out:
        raise FitError("nothing to vary: give at least one --vary PATH.PROPERTY[=LO:HI]")
    return out


def _variant(prim: Usd.Prim, spec: dict, text: str, where: str) -> list[Parameter]:
    sets = prim.GetVariantSets()
    name = spec["set"]
    if not sets.HasVariantSet(name):
        have = ", ".join(sets.GetNames()) or "none"
        raise FitError(f"{prim.GetPath()} has no variant set {name!r} (it has: {have})", where)
    vset = sets.GetVariantSet(name)
    names = list(vset.GetVariantNames())
    choices = names
    if spec["range"] is not None:
        choices = [c.strip() for c in spec["range"].split(",") if c.strip()]
        unknown = [c for c in choices if c not in names]
        if unknown:
            raise FitError(f"variant set {name!r} has no variant {unknown[0]!r} (it has: "
                           f"{', '.join(names)})", where)
        if len(set(choices)) != len(choices):
            raise FitError("a variant is listed twice", where)
    if len(choices) < 2:
        raise FitError(f"needs at least two variants to choose from, got "
                       f"{', '.join(choices) or 'none'}", where)
    current = vset.GetVariantSelection()
    start = current if current in choices else choices[0]
    return [Parameter(f"{spec['path']}{{{name}}}", str(prim.GetPath()), None, (), 0.0,
                      float(len(choices) - 1), start, tuple(choices), name, "variant",
                      clipped=current not in choices)]


def _numeric(prim: Usd.Prim, spec: dict, text: str, where: str) -> list[Parameter]:
    prop = spec["prop"]
    if prop.startswith(_REFUSED):
        raise FitError("lumitrace's results are written by it, not fitted", where)
    attr = prim.GetAttribute(prop)
    if not attr or not attr.GetTypeName():
        if prim.HasRelationship(prop):
            raise FitError(f"{prop} is a relationship, not a number", where)
        raise FitError(f"{prim.GetPath()} has no attribute {prop}", where)
    type_name = attr.GetTypeName()
    scalar = str(type_name.scalarType)
    kind = "integer" if _INTEGER.match(scalar) else "real" if _REAL.match(scalar) else None
    if kind is None:
        raise FitError(f"is a {type_name} attribute, not a number: it cannot be fitted "
                       "(a variant set can: --vary PATH{SET})", where)
    if attr.GetNumTimeSamples() > 0:
        raise FitError("has time samples: a value the fit authors would not show at them "
                       "(fit a stage whose value is not animated)", where)
    if prop.startswith("xformOp:") and UsdGeom.Xformable(prim) and \
            prop not in [op.GetOpName() for op in UsdGeom.Xformable(prim).GetOrderedXformOps()]:
        raise FitError(f"is not in the prim's xformOpOrder: changing it moves nothing", where)
    if prop in PROFILE_ATTRIBUTES and prop != PROFILE_POINTS:
        raise FitError("the profile's kind, segments and length shape its mesh's faces, not "
                       "its curve: vary its points (lumitrace:profile:points[i][0 or 1])", where)
    if prop == PROFILE_POINTS and not prim.IsA(UsdGeom.Mesh):
        raise FitError(f"a profile makes a Mesh's points; {prim.GetPath()} is a "
                       f"{prim.GetTypeName() or 'typeless'} prim", where)
    value = attr.Get()
    elements = _element(value, spec["index"], type_name, where)
    schema_range = MATERIAL_RANGES.get(prop)
    revolve = prop == PROFILE_POINTS and prim.GetAttribute(PROFILE_KIND).Get() != "extrude"
    out = []
    array = np.asarray(value, dtype=np.float64)
    for index in elements:
        name = _spelling(text, index)
        start = float(array[index])
        pwhere = f"--vary {name}" if len(elements) > 1 else where
        if spec["range"] is None:
            if schema_range is None:
                raise FitError("has no range of its own: give one, "
                               f"{name}=LO:HI or {name}=+-D", pwhere)
            lo, hi = schema_range
        else:
            lo, hi = _range(spec["range"], start, pwhere)
        domain = (0.0, math.inf) if revolve and index[-1:] == (0,) else schema_range
        if domain is not None:
            s_lo, s_hi = domain
            if spec["range"] is not None and spec["range"].strip().startswith(("+-", "±")):
                lo, hi = max(lo, s_lo), min(hi, s_hi)
            if lo < s_lo or hi > s_hi:
                what = "a revolved profile's radii [0, inf)" if domain is not schema_range \
                    else f"the attribute's own [{s_lo:g}, {s_hi:g}]"
                raise FitError(f"the range {lo:g}:{hi:g} leaves {what}", pwhere)
        if kind == "integer":
            lo_i, hi_i = math.ceil(lo), math.floor(hi)
            if hi_i <= lo_i:
                raise FitError(f"the range {lo:g}:{hi:g} holds fewer than two whole numbers",
                               pwhere)
            choices = tuple(range(lo_i, hi_i + 1))
            start_i = int(min(max(round(start), lo_i), hi_i))
            out.append(Parameter(name, str(prim.GetPath()), prop, index, lo_i, hi_i, start_i,
                                 choices, None, str(type_name),
                                 clipped=start_i != round(start),
                                 schema_range=schema_range))
            continue
        clipped = not lo <= start <= hi
        out.append(Parameter(name, str(prim.GetPath()), prop, index, lo, hi,
                             min(max(start, lo), hi), (), None, str(type_name),
                             clipped=clipped, schema_range=schema_range))
    return out
