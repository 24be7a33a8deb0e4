"""Read a luminaire stage into the flat :class:`~lumitrace.scene.Scene` the tracer works on.

What is read, and how:

- **The luminaire** is the prim ``luminaire`` if given, else the stage's default prim, else
  its first root prim. Only what lies below it is read.
- **Units and axes.** Triangles and emitter transforms are converted to world metres with
  ``metersPerUnit``; directions stay in the stage's own axes (``upAxis`` Y or Z is reported,
  nothing is rotated).
- **Geometry.** ``UsdGeom.Mesh`` prims (polygons fan-triangulated as Hydra does, faces listed
  in ``holeIndices`` dropped) and the implicit ``Cube``, ``Sphere``, ``Cylinder``, ``Cone``
  and ``Plane`` (tessellated); other gprims are skipped with a warning. Native instances are
  traversed as instance proxies, ``UsdGeom.PointInstancer`` prototypes are placed at every
  instance (its mask, ``invisibleIds`` and ``inactiveIds``, applies). Invisible prims and
  purposes other than ``default`` and ``render`` are skipped. Front faces are made
  counter-clockwise in the right-handed world: a ``leftHanded`` orientation and a mirroring
  transform (negative determinant) each flip the winding. Zero-area triangles are dropped
  with a warning. The dielectric faces of a gprim that form a closed surface facing inward
  (negative volume: flipped normals) are flipped to face the air, with a warning.
- **The file and its composition.** A file named ``.usda``, ``.usdc``, ``.usd`` or
  ``.usdz`` must start like one (a huge bogus file is refused without reading it). A
  missing layer, a composition cycle or a reference to a missing prim is an error within
  the luminaire, a warning elsewhere. USD's own warnings become scene warnings instead of
  being printed.
- **Materials.** The bound material (``full`` purpose, else all-purpose; ``GeomSubset``
  bindings per face) is read in three layers, each overriding the previous one:
  its ``UsdPreviewSurface`` (see :func:`preview_surface_values`), the ``LumitraceMaterialAPI``
  on the Material prim, the ``LumitraceMaterialAPI`` on the gprim. Where the API is applied
  all its attributes count (schema fallbacks included); where it is not, only authored
  ``lumitrace:*`` attributes do. A gprim with no material gets diffuse 0.8.
- **Emitters.** ``UsdLux`` Sphere, Disk, Rect and Cylinder lights; see :func:`light_flux`.

Every bad value raises :class:`~lumitrace.errors.StageError` naming prim and property
(the rules live in :mod:`lumitrace.stage.validate`); imperfect but traceable input only
adds to ``Scene.warnings``.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Iterable

import numpy as np
from pxr import Pcp, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade, UsdUtils

from .. import schema
from ..errors import StageError
from ..scene import Emitter, Material, Scene
from ..scene.shaping import shaping_emits, shaping_fraction, unshaped_cone_angle
from . import validate
from .validate import Sourced
from ..filenames import RESULT_LAYER_SUFFIX

#: Rec.709 / sRGB luminance weights (linear RGB -> relative luminance Y).
REC709_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: Path of the default material given to gprims with no material (no prim has it).
DEFAULT_MATERIAL_PATH = ""

#: UsdPreviewSurface mapping thresholds (see :func:`preview_surface_values`).
METALLIC_THRESHOLD = 0.5
MIRROR_ROUGHNESS = 0.05
SPECULAR_WORKFLOW_THRESHOLD = 0.5

#: Tessellation of implicit gprims: segments around, rings from pole to pole.
TESSELLATION_SEGMENTS = 64
TESSELLATION_RINGS = 32

#: A triangle is dropped when |e1 x e2| <= this * (longest edge)^2.
DEGENERATE_TOLERANCE = 1e-10

_LIGHT_TYPES = (
    (UsdLux.SphereLight, "sphere"),
    (UsdLux.DiskLight, "disk"),
    (UsdLux.RectLight, "rect"),
    (UsdLux.CylinderLight, "cylinder"),
)
_IMPLICIT_GPRIMS = ("Cube", "Sphere", "Cylinder", "Cone", "Plane")
_RENDERED_PURPOSES = (UsdGeom.Tokens.default_, UsdGeom.Tokens.render)
_PURPOSES = (UsdGeom.Tokens.default_, UsdGeom.Tokens.render, UsdGeom.Tokens.proxy,
             UsdGeom.Tokens.guide)
_VISIBILITIES = (UsdGeom.Tokens.inherited, UsdGeom.Tokens.invisible)
_ORIENTATIONS = (UsdGeom.Tokens.rightHanded, UsdGeom.Tokens.leftHanded)
_AXES = ("X", "Y", "Z")
_EMITTER_FIELDS = {f.name for f in fields(Emitter)}


# --------------------------------------------------------------------------------------
# Public functions
# --------------------------------------------------------------------------------------

def read_stage(path: str | Path, luminaire: str | None = None, *,
               time: Usd.TimeCode | float | None = None) -> Scene:
    """Open the stage file ``path`` and read its luminaire into a :class:`Scene`.

    Parameters
    ----------
    path : str or Path
        A USD file (``.usda``, ``.usdc``, ``.usd``, ``.usdz``).
    luminaire : str, optional
        Prim path of the luminaire; default: the default prim, else the first root prim.
    time : Usd.TimeCode or float, optional
        Time to read values at; default ``Usd.TimeCode.Default()``.

    Raises
    ------
    StageError
        The file is missing or not a USD stage, or the stage has no luminaire, no emitter
        or a bad value; the message names the file or the prim and property.
    """
    file = Path(path)
    if not file.exists():
        raise StageError("stage file not found", str(file))
    if file.is_dir():
        raise StageError("is a folder, not a USD stage file", str(file))
    file = file.resolve()
    validate.check_layer_file(file)
    with _UsdDiagnostics() as diagnostics:
        try:
            stage = Usd.Stage.Open(str(file), Usd.Stage.LoadAll)
        except Tf.ErrorException as exc:
            raise StageError(f"cannot open as a USD stage: {_tf_message(exc)}",
                             str(file)) from exc
        if stage is None:
            raise StageError("cannot open as a USD stage", str(file))
        return _read(stage, luminaire, time, diagnostics)


def scene_from_stage(stage: Usd.Stage, luminaire: str | None = None, *,
                     time: Usd.TimeCode | float | None = None) -> Scene:
    """Read the luminaire of an open stage into a :class:`Scene` (see :func:`read_stage`).

    The stage's composed state is read as it is, unsaved edits included.
    """
    with _UsdDiagnostics() as diagnostics:
        return _read(stage, luminaire, time, diagnostics)


def _read(stage: Usd.Stage, luminaire: str | None, time, diagnostics: "_UsdDiagnostics") -> Scene:
    layer = stage.GetRootLayer()
    stage_file = str(Path(layer.realPath).resolve()) if layer.realPath else ""
    label = stage_file or layer.identifier
    try:
        # every value read is checked explicitly: numpy's warnings about the NaN, Inf or
        # overflow those checks catch would only add lines to the one error a user sees
        with np.errstate(all="ignore"):
            return _Reader(stage, _timecode(time), stage_file, label, diagnostics).read(luminaire)
    except Tf.ErrorException as exc:
        raise StageError(f"USD error while reading the stage: {_tf_message(exc)}",
                         label) from exc


class _UsdDiagnostics:
    """While in use, USD's warnings and status messages are collected instead of printed
    (bad input must give one clear error, and nothing else, on stderr); the reader reports
    them as scene warnings, and composition errors itself."""

    def __enter__(self) -> "_UsdDiagnostics":
        self._delegate = UsdUtils.CoalescingDiagnosticDelegate()
        return self

    def __exit__(self, *exc) -> None:
        self._delegate = None  # unregisters it

    def take(self) -> list[str]:
        """The messages collected so far (composition errors left out)."""
        notes = []
        for d in self._delegate.TakeUncoalescedDiagnostics():
            if d.sourceFunction.endswith("UsdStage::_ReportErrors"):
                continue
            notes.append(" ".join(_NAMESPACE.sub("", d.commentary).split())[:300])
        return notes


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


# --------------------------------------------------------------------------------------
# The reader
# --------------------------------------------------------------------------------------

@dataclass
class _Frame:
    """Where gprims found by a walk are placed.

    ``anchor`` None: at their own world transform. Otherwise they belong to a PointInstancer
    prototype rooted at ``anchor`` and are placed once per base: a row-vector matrix from the
    prototype root's space to the world (stage units) and a label for emitter paths.
    """

    anchor: Usd.Prim | None = None
    bases: list[tuple[np.ndarray, str]] = field(default_factory=list)


@dataclass
class _LocalMesh:
    """A gprim's triangles in its local space, before placement."""

    triangles: np.ndarray        # (T, 3, 3) float64, local units, front faces CCW
    material_index: np.ndarray   # (T,) int32


class _Reader:
    def __init__(self, stage: Usd.Stage, time: Usd.TimeCode, stage_file: str, label: str,
                 diagnostics: _UsdDiagnostics):
        self.stage = stage
        self.diagnostics = diagnostics
        self.time = time
        self.stage_file = stage_file
        self.label = label
        self.xf = UsdGeom.XformCache(time)
        self.triangles: list[np.ndarray] = []
        self.material_index: list[np.ndarray] = []
        self.part_index: list[np.ndarray] = []
        self.parts: dict[str, int] = {}
        self.materials: dict[str, int] = {}
        self.material_list: list[Material] = []
        self.emitters: list[Emitter] = []
        self.warnings: dict[str, None] = {}
        self.local_meshes: dict[str, _LocalMesh | None] = {}
        self.unbound: list[str] = []
        self.meters_per_unit = 1.0

    # -- top level ----------------------------------------------------------------------

    def read(self, luminaire: str | None) -> Scene:
        root = self._luminaire_prim(luminaire)
        root_path = str(root.GetPath())
        layer_where = self.stage_file or self.label
        if not UsdGeom.StageHasAuthoredMetersPerUnit(self.stage):
            self._warn(f"{layer_where}: metersPerUnit is not authored: assuming centimetres "
                       "(USD's fallback, 0.01 m per unit)")
        self.meters_per_unit = float(UsdGeom.GetStageMetersPerUnit(self.stage))
        validate.check_stage_units(self.meters_per_unit, layer_where)
        up_axis = str(UsdGeom.GetStageUpAxis(self.stage))
        validate.check_up_axis(up_axis, layer_where)
        self._check_composition(root, layer_where)

        if self._visible_and_rendered(root, computed=True):
            self._walk(root, _Frame())
        if self.unbound:
            example = self.unbound[0]
            more = f" and {len(self.unbound) - 1} more" if len(self.unbound) > 1 else ""
            self._warn(f"{example}{more}: no material bound: using diffuse reflectance "
                       f"{schema.MATERIAL_FALLBACKS[schema.REFLECTANCE]:g}")
        if not self.emitters:
            raise StageError("no emitter: the luminaire has no active, visible Sphere, Disk, "
                             f"Rect or Cylinder light (in {self.label})", root_path)

        for note in self.diagnostics.take():
            self._warn(f"{self.label}: USD: {note}")
        if self.triangles:
            triangles = np.concatenate(self.triangles)
            material_index = np.concatenate(self.material_index).astype(np.int32)
            part_index = np.concatenate(self.part_index).astype(np.int32)
        else:
            triangles = np.zeros((0, 3, 3))
            material_index = np.zeros(0, dtype=np.int32)
            part_index = np.zeros(0, dtype=np.int32)
        return Scene(
            triangles=triangles,
            material_index=material_index,
            part_index=part_index,
            materials=tuple(self.material_list),
            parts=tuple(self.parts),
            emitters=tuple(self.emitters),
            up_axis=up_axis,
            meters_per_unit=self.meters_per_unit,
            luminaire_path=root_path,
            stage_path=self.stage_file,
            warnings=tuple(self.warnings),
        )

    def _check_composition(self, root: Usd.Prim, layer_where: str) -> None:
        """Composition errors that leave the luminaire incomplete (a missing layer, a cycle,
        a reference to no prim) are bad input; elsewhere in the stage they are warnings, as
        is a missing result layer of ours (the next run writes it again)."""
        root_path = root.GetPath()
        for error in self.stage.GetCompositionErrors():
            message = _ANON_LAYER.sub("", _tf_message(error))
            site = error.rootSite.path
            what = _FATAL_COMPOSITION.get(error.errorType)
            sublayer = error.errorType in _SUBLAYER_ERRORS
            where = layer_where if sublayer or site.IsAbsoluteRootPath() else str(site)
            ours = sublayer and RESULT_LAYER_SUFFIX in message
            inside = (site.IsAbsoluteRootPath() or site.HasPrefix(root_path)
                      or root_path.HasPrefix(site))
            if what is not None and inside and not ours:
                prop = "subLayers" if sublayer else _arc_property(message)
                raise StageError(f"{what}: {message}", where, prop)
            self._warn(f"{where}: composition error: {message}")

    def _luminaire_prim(self, luminaire: str | None) -> Usd.Prim:
        if luminaire is not None:
            if not Sdf.Path.IsValidPathString(str(luminaire)):
                raise StageError(f"not a valid prim path (in {self.label})", str(luminaire))
            prim = self.stage.GetPrimAtPath(str(luminaire))
            if not prim or not prim.IsActive():
                raise StageError(f"no such active prim in {self.label}", str(luminaire))
            return prim
        if self.stage.HasDefaultPrim():
            prim = self.stage.GetDefaultPrim()
            if not prim or not prim.IsActive():
                name = self.stage.GetRootLayer().defaultPrim
                raise StageError(f"defaultPrim names {name!r}, which is not an active prim",
                                 self.label)
            return prim
        children = self.stage.GetPseudoRoot().GetChildren()
        if not children:
            raise StageError("the stage is empty: no luminaire prim", self.label)
        prim = children[0]
        self._warn(f"{self.label}: no defaultPrim: using the first root prim {prim.GetPath()}")
        return prim

    # -- traversal ------------------------------------------------------------------------

    def _walk(self, root: Usd.Prim, frame: _Frame) -> None:
        if frame.anchor is None:
            predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
        else:  # prototypes may sit under an "over" or "class" to hide them from traversals
            predicate = Usd.TraverseInstanceProxies(Usd.PrimIsActive & Usd.PrimIsLoaded)
        it = iter(Usd.PrimRange(root, predicate))
        for prim in it:
            if not self._visible_and_rendered(prim, computed=False):
                it.PruneChildren()
                continue
            kind = _light_kind(prim)
            if kind is not None:
                self._light(prim, kind, frame)
                continue
            if prim.HasAPI(UsdLux.LightAPI) and not prim.IsA(UsdGeom.Gprim):
                self._warn(f"{prim.GetPath()}: {prim.GetTypeName() or 'light'} is not "
                           "supported (Sphere, Disk, Rect and Cylinder lights are): skipped")
                continue
            if prim.IsA(UsdGeom.PointInstancer):
                self._point_instancer(prim, frame)
                it.PruneChildren()
                continue
            if prim.GetTypeName() and prim.GetPrimTypeInfo().GetSchemaType().isUnknown:
                self._warn(f"{prim.GetPath()}: unknown prim type {str(prim.GetTypeName())!r}: "
                           "not a surface or light lumitrace knows; its children are read")
                continue
            if prim.IsA(UsdGeom.Gprim):
                if prim.HasAPI(UsdLux.LightAPI):
                    self._warn(f"{prim.GetPath()}: mesh lights are not supported: traced as "
                               "a plain surface without emission")
                self._gprim(prim, frame)

    def _visible_and_rendered(self, prim: Usd.Prim, computed: bool) -> bool:
        imageable = UsdGeom.Imageable(prim)
        if not imageable:
            return True
        path = str(prim.GetPath())
        visibility = validate.check_token(imageable.GetVisibilityAttr().Get(self.time),
                                          _VISIBILITIES, path, "visibility")
        validate.check_token(imageable.GetPurposeAttr().Get(), _PURPOSES, path, "purpose")
        if computed:
            visibility = imageable.ComputeVisibility(self.time)
        # else: ancestors were checked on the way down
        if visibility == UsdGeom.Tokens.invisible:
            return False
        return imageable.ComputePurpose() in _RENDERED_PURPOSES

    def _point_instancer(self, prim: Usd.Prim, frame: _Frame) -> None:
        path = str(prim.GetPath())
        instancer = UsdGeom.PointInstancer(prim)
        prototypes = instancer.GetPrototypesRel().GetForwardedTargets()
        proto_indices = _array(instancer.GetProtoIndicesAttr().Get(self.time), path,
                               "protoIndices", np.int64)
        if proto_indices.size == 0:
            self._warn(f"{path}: point instancer has no instances")
            return
        for name, size in (("positions", 3), ("orientations", 4), ("orientationsf", 4),
                           ("scales", 3)):
            attr = prim.GetAttribute(name)
            arr = _array(attr.Get(self.time) if attr else None, path, name, width=size)
            if len(arr):
                validate.check_finite_points(arr, path, name, what=name)
        if proto_indices.min() < 0 or proto_indices.max() >= len(prototypes):
            raise StageError(f"indexes prototype {int(proto_indices.max())} but there are "
                             f"{len(prototypes)} prototypes", path, "protoIndices")
        mats = instancer.ComputeInstanceTransformsAtTime(
            self.time, self.time, UsdGeom.PointInstancer.IncludeProtoXform,
            UsdGeom.PointInstancer.IgnoreMask)
        if len(mats) != proto_indices.size:
            raise StageError(f"{proto_indices.size} protoIndices but {len(mats)} instance "
                             "transforms (positions, orientations and scales must match)",
                             path, "positions")
        mats = np.asarray([np.array(m) for m in mats], dtype=np.float64)
        validate.check_finite_matrix(mats, path, "positions")
        mask = np.asarray(instancer.ComputeMaskAtTime(self.time) or [True] * len(mats),
                          dtype=bool)
        placements = self._placements(prim, frame)
        for proto_number, target in enumerate(prototypes):
            proto = self.stage.GetPrimAtPath(target)
            if not proto:
                raise StageError(f"prototype {target} does not exist", path, "prototypes")
            chosen = np.flatnonzero((proto_indices == proto_number) & mask)
            if chosen.size == 0:
                continue
            bases = [(mats[i] @ world, f"{label}[{path}:{i}]")
                     for world, label in placements for i in chosen]
            self._walk(proto, _Frame(proto, bases))

    def _placements(self, prim: Usd.Prim, frame: _Frame) -> list[tuple[np.ndarray, str]]:
        """Row-vector local-to-world matrices (stage units) of ``prim``, one per placement."""
        try:
            if frame.anchor is None:
                local = np.array(self.xf.GetLocalToWorldTransform(prim))
                if not np.isfinite(local).all():
                    self._raise_bad_transform(prim)
                return [(local, "")]
            relative, _ = self.xf.ComputeRelativeTransform(prim, frame.anchor)
        except Tf.ErrorException as exc:  # e.g. an op whose value has the wrong type
            self._raise_bad_transform(prim, exc)
        relative = np.array(relative)
        if not np.isfinite(relative).all():
            self._raise_bad_transform(prim)
        return [(relative @ base, label) for base, label in frame.bases]

    def _raise_bad_transform(self, prim: Usd.Prim, exc: Exception | None = None,
                             singular: bool = False) -> None:
        """Name the prim and xformOp whose transform cannot be evaluated, is NaN or
        infinite, or (``singular``) collapses space (a zero scale)."""
        what = ("transform collapses a light to nothing (a scale of 0): it has no emitting "
                "surface or direction" if singular else "transform is NaN or infinite")
        p = prim
        while p and not p.IsPseudoRoot():
            xformable = UsdGeom.Xformable(p)
            if xformable:
                for op in xformable.GetOrderedXformOps():
                    try:
                        m = np.array(op.GetOpTransform(self.time))
                    except Tf.ErrorException as op_exc:
                        raise StageError(f"transform op cannot be evaluated: "
                                         f"{_tf_message(op_exc)}", str(p.GetPath()),
                                         op.GetName()) from op_exc
                    if not np.isfinite(m).all() or (singular and not _invertible(m[:3, :3])):
                        raise StageError(what, str(p.GetPath()), op.GetName())
            p = p.GetParent()
        if exc is not None:
            raise StageError(f"transform cannot be evaluated: {_tf_message(exc)}",
                             str(prim.GetPath()), "xformOpOrder") from exc
        raise StageError("world " + what, str(prim.GetPath()), "xformOpOrder")

    # -- geometry -------------------------------------------------------------------------

    def _gprim(self, prim: Usd.Prim, frame: _Frame) -> None:
        path = str(prim.GetPath())
        if path not in self.local_meshes:
            self.local_meshes[path] = self._local_mesh(prim)
        local = self.local_meshes[path]
        if local is None or len(local.triangles) == 0:
            return
        part = self.parts.setdefault(path, len(self.parts))
        flat = local.triangles.reshape(-1, 3)
        for matrix, _ in self._placements(prim, frame):
            world = (flat @ matrix[:3, :3] + matrix[3, :3]) * self.meters_per_unit
            world = world.reshape(-1, 3, 3)
            validate.check_extent(world, path, "points")
            if np.linalg.det(matrix[:3, :3]) < 0.0:  # a mirroring transform flips winding
                world = world[:, [0, 2, 1]]
            keep = _non_degenerate(world)
            dropped = int(keep.size - np.count_nonzero(keep))
            if dropped:
                self._warn(f"{path}: {dropped} zero-area triangle(s) dropped")
            self.triangles.append(world[keep])
            self.material_index.append(local.material_index[keep])
            self.part_index.append(np.full(int(np.count_nonzero(keep)), part, dtype=np.int32))

    def _local_mesh(self, prim: Usd.Prim) -> _LocalMesh | None:
        path = str(prim.GetPath())
        type_name = str(prim.GetTypeName())
        if prim.IsA(UsdGeom.Mesh):
            polygons = self._mesh_polygons(prim)
        elif type_name in _IMPLICIT_GPRIMS:
            polygons = _implicit_polygons(prim, self.time)
        else:
            self._warn(f"{path}: {type_name or 'untyped gprim'} is not a surface lumitrace "
                       "traces (Mesh, Cube, Sphere, Cylinder, Cone, Plane are): skipped")
            return None
        if polygons is None:
            return None
        points, counts, indices, keep_face = polygons
        triangles, face_of_triangle = _triangulate(points, counts, indices, keep_face)
        orientation = validate.check_token(UsdGeom.Gprim(prim).GetOrientationAttr().Get(self.time),
                                           _ORIENTATIONS, path, "orientation")
        if orientation == UsdGeom.Tokens.leftHanded:
            triangles = triangles[:, [0, 2, 1]]
        if len(triangles) == 0:
            self._warn(f"{path}: no faces: skipped")
            return None
        face_material = self._face_materials(prim, counts.size)
        material_index = face_material[face_of_triangle].astype(np.int32)
        dielectric = np.array([m.scattering == "dielectric" for m in self.material_list],
                              dtype=bool)[material_index]
        if dielectric.any():
            triangles = self._orient_dielectric(path, triangles, dielectric)
        return _LocalMesh(triangles, material_index)

    def _orient_dielectric(self, path: str, triangles: np.ndarray,
                           dielectric: np.ndarray) -> np.ndarray:
        """Make the dielectric faces of a gprim face the air.

        The tracer tells the inside of a dielectric from the winding (front = outside). When
        the dielectric faces form a closed, consistently wound surface, its signed volume
        says which way they face: a negative volume means they all point inward (a mesh
        exported with flipped normals), and they are flipped, with a warning. The volume of
        the whole surface is used, so a hollow part, whose inner surface rightly faces its
        cavity, keeps its orientation. A surface that is open or inconsistently wound cannot
        be judged: a warning says its winding is taken as it is.
        """
        faces = triangles[dielectric]
        closed, volume = _closed_surface_volume(faces)
        if not closed:
            self._warn(f"{path}: dielectric faces do not form a closed, consistently wound "
                       "surface: their inside is taken from the winding (counter-clockwise "
                       "= outside)")
        elif volume < 0.0:
            self._warn(f"{path}: the closed dielectric surface faces inward (negative "
                       "volume, normals flipped): its faces are flipped to face the air")
            triangles = triangles.copy()
            triangles[dielectric] = faces[:, [0, 2, 1]]
        return triangles

    def _mesh_polygons(self, prim: Usd.Prim):
        path = str(prim.GetPath())
        mesh = UsdGeom.Mesh(prim)
        points = _array(mesh.GetPointsAttr().Get(self.time), path, "points", width=3)
        if len(points) == 0:
            self._warn(f"{path}: mesh has no points: skipped")
            return None
        validate.check_finite_points(points, path, "points")
        counts = _array(mesh.GetFaceVertexCountsAttr().Get(self.time), path,
                        "faceVertexCounts", np.int64)
        indices = _array(mesh.GetFaceVertexIndicesAttr().Get(self.time), path,
                         "faceVertexIndices", np.int64)
        validate.check_face_topology(counts, indices, len(points), path)
        keep_face = counts >= 3
        small = int(counts.size - np.count_nonzero(keep_face))
        if small:
            self._warn(f"{path}: {small} face(s) with fewer than 3 vertices ignored")
        holes = _array(mesh.GetHoleIndicesAttr().Get(self.time), path, "holeIndices", np.int64)
        if holes.size:
            valid = holes[(holes >= 0) & (holes < counts.size)]
            keep_face[valid] = False
        return points, counts, indices, keep_face

    # -- materials ------------------------------------------------------------------------

    def _face_materials(self, prim: Usd.Prim, n_faces: int) -> np.ndarray:
        face_material = np.full(n_faces, self._material_for(prim, prim), dtype=np.int32)
        binding = UsdShade.MaterialBindingAPI(prim)
        for subset in binding.GetMaterialBindSubsets():
            subset_prim = subset.GetPrim()
            if not subset_prim.IsActive():
                continue
            faces = _array(subset.GetIndicesAttr().Get(self.time), str(subset_prim.GetPath()),
                           "indices", np.int64)
            inside = faces[(faces >= 0) & (faces < n_faces)]
            if inside.size != faces.size:
                self._warn(f"{subset_prim.GetPath()}: {faces.size - inside.size} indices "
                           "outside the mesh's faces ignored")
            face_material[inside] = self._material_for(prim, subset_prim)
        return face_material

    def _material_for(self, gprim: Usd.Prim, bind_prim: Usd.Prim) -> int:
        """Index of the material of ``bind_prim`` (the gprim or one of its subsets)."""
        gprim_path = str(gprim.GetPath())
        material, _ = UsdShade.MaterialBindingAPI(bind_prim).ComputeBoundMaterial(
            UsdShade.Tokens.full)
        material_prim = material.GetPrim() if material else None
        gprim_values = _material_api_values(gprim, self.time)
        if _has_api(gprim, schema.MATERIAL_API):  # every value comes from the gprim
            key = gprim_path
        elif gprim_values:  # some values from the gprim, the rest from this binding
            key = str(bind_prim.GetPath())
        elif material_prim is not None:
            key = str(material_prim.GetPath())
        else:
            key = DEFAULT_MATERIAL_PATH
            self.unbound.append(gprim_path)
        if key in self.materials:
            return self.materials[key]

        values = {name: Sourced(value, key or gprim_path, name)
                  for name, value in schema.MATERIAL_FALLBACKS.items()}
        if material_prim is not None:
            values.update(self._preview_values(material))
            values.update(_material_api_values(material_prim, self.time))
        values.update(gprim_values)
        validate.check_material(values)
        mat = Material(
            path=key,
            scattering=str(values[schema.SCATTERING].value),
            reflectance=float(values[schema.REFLECTANCE].value),
            specular_reflectance=float(values[schema.SPECULAR_REFLECTANCE].value),
            transmittance=float(values[schema.TRANSMITTANCE].value),
            ior=float(values[schema.IOR].value),
            roughness=float(values[schema.ROUGHNESS].value),
        )
        self.materials[key] = len(self.material_list)
        self.material_list.append(mat)
        return self.materials[key]

    def _preview_values(self, material: UsdShade.Material) -> dict[str, Sourced]:
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
            value, source = self._shader_input(shader, name, default)
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
        return {name: Sourced(value, *sources[origin[name]]) if origin[name] in sources
                else Sourced(value, where, name)
                for name, value in derived.items()}

    def _shader_input(self, shader: UsdShade.Shader, name: str, default):
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
            self._warn(f"{where[0]}.{where[1]}: connected to a texture or node output: "
                       f"using the UsdPreviewSurface default {default!r}")
            return default, where
        value = attr.Get(self.time)
        source = (str(attr.GetPrim().GetPath()), attr.GetName())
        if value is None:
            return default, source
        if isinstance(value, (bool, int, float)):
            return value, source
        try:
            return tuple(float(v) for v in value), source
        except TypeError:
            return value, source

    # -- emitters -------------------------------------------------------------------------

    def _light(self, prim: Usd.Prim, kind: str, frame: _Frame) -> None:
        path = str(prim.GetPath())
        light = UsdLux.LightAPI(prim)
        dims: dict[str, float | bool] = {}
        if kind == "sphere":
            sphere = UsdLux.SphereLight(prim)
            dims["radius"] = validate.check_non_negative(
                sphere.GetRadiusAttr().Get(self.time), path, "inputs:radius")
            dims["treat_as_point"] = bool(sphere.GetTreatAsPointAttr().Get(self.time))
        elif kind == "disk":
            dims["radius"] = validate.check_positive(
                UsdLux.DiskLight(prim).GetRadiusAttr().Get(self.time), path, "inputs:radius")
        elif kind == "rect":
            rect = UsdLux.RectLight(prim)
            dims["width"] = validate.check_positive(rect.GetWidthAttr().Get(self.time), path,
                                                    "inputs:width")
            dims["height"] = validate.check_positive(rect.GetHeightAttr().Get(self.time), path,
                                                     "inputs:height")
            if rect.GetTextureFileAttr().Get(self.time):
                self._warn(f"{path}.inputs:texture:file: light textures are ignored")
        else:
            cylinder = UsdLux.CylinderLight(prim)
            dims["length"] = validate.check_positive(cylinder.GetLengthAttr().Get(self.time),
                                                     path, "inputs:length")
            dims["radius"] = validate.check_positive(cylinder.GetRadiusAttr().Get(self.time),
                                                     path, "inputs:radius")
        cone_angle, cone_softness, focus = self._shaping(prim, kind)

        flux_attr = prim.GetAttribute(schema.LUMINOUS_FLUX)
        authored_flux = None
        if flux_attr and flux_attr.HasAuthoredValue():
            authored_flux = validate.check_luminous_flux(flux_attr.Get(self.time), path,
                                                         schema.LUMINOUS_FLUX)
        elif not light.GetIntensityAttr().HasAuthoredValue():
            raise StageError("light has no luminous flux: author lumitrace:luminousFlux (lm) "
                             "or inputs:intensity", path)
        else:
            intensity = validate.check_non_negative(light.GetIntensityAttr().Get(self.time),
                                                    path, "inputs:intensity")
            exposure = validate.check_finite(light.GetExposureAttr().Get(self.time), path,
                                             "inputs:exposure")
            color = _array(light.GetColorAttr().Get(self.time), path, "inputs:color",
                           width=3).ravel()
            if color.size != 3 or not np.isfinite(color).all() or (color < 0).any():
                raise StageError(f"must be finite and >= 0, got {tuple(color)}", path,
                                 "inputs:color")
            normalize = bool(light.GetNormalizeAttr().Get(self.time))
            fraction = shaping_fraction(kind, cone_angle, cone_softness, focus)

        for matrix, label in self._placements(prim, frame):
            to_world = np.diag([self.meters_per_unit] * 3 + [1.0]) @ matrix.T
            validate.check_extent(to_world[:3, 3], path, "xformOpOrder")
            validate.check_extent(np.abs(to_world[:3, :3]).sum(axis=0) * max(
                v for v in dims.values() if not isinstance(v, bool)), path, "xformOpOrder")
            if not _invertible(matrix[:3, :3]):
                self._raise_bad_transform(prim, singular=True)
            if authored_flux is not None:
                flux = authored_flux
            else:
                area = _world_area(kind, dims, to_world[:3, :3])
                flux = light_flux(kind, intensity, exposure, color, normalize, area, fraction)
                if not (math.isfinite(flux) and flux > 0.0):
                    raise StageError(f"light emits no {'finite ' if flux else ''}flux "
                                     f"({flux:g} lm from intensity "
                                     f"{intensity:g}, exposure {exposure:g}, world area "
                                     f"{area:g} m^2)", path, "inputs:intensity")
            extra = {"focus": focus} if "focus" in _EMITTER_FIELDS else {}
            self.emitters.append(Emitter(
                path=path + label, kind=kind, flux=float(flux), to_world=to_world,
                cone_angle=cone_angle, cone_softness=cone_softness, **dims, **extra))

    def _shaping(self, prim: Usd.Prim, kind: str) -> tuple[float, float, float]:
        """Cone angle (deg), softness and focus; unshaped: 90 deg for one-sided lights,
        180 deg (all directions) for sphere and cylinder lights."""
        path = str(prim.GetPath())
        unshaped = unshaped_cone_angle(kind)
        if not prim.HasAPI(UsdLux.ShapingAPI):
            return unshaped, 0.0, 0.0
        shaping = UsdLux.ShapingAPI(prim)
        angle_attr = shaping.GetShapingConeAngleAttr()
        angle, softness, focus = unshaped, 0.0, 0.0
        if angle_attr.HasAuthoredValue():
            angle = validate.check_positive(angle_attr.Get(self.time), path,
                                            "inputs:shaping:cone:angle")
            angle = min(angle, 180.0)
        softness_attr = shaping.GetShapingConeSoftnessAttr()
        if softness_attr.HasAuthoredValue():
            softness = min(validate.check_non_negative(softness_attr.Get(self.time), path,
                                                       "inputs:shaping:cone:softness"), 1.0)
        focus_attr = shaping.GetShapingFocusAttr()
        if focus_attr.HasAuthoredValue():
            focus = validate.check_non_negative(focus_attr.Get(self.time), path,
                                                "inputs:shaping:focus")
        if shaping.GetShapingIesFileAttr().Get(self.time):
            self._warn(f"{path}.inputs:shaping:ies:file: IES profiles on emitters are ignored")
        if kind == "cylinder" and (angle < unshaped or focus > 0.0):
            self._warn(f"{path}: shaping of a CylinderLight is ignored")
            return unshaped, 0.0, 0.0
        if focus > 0.0 and "focus" not in _EMITTER_FIELDS:
            self._warn(f"{path}.inputs:shaping:focus: focus is not supported: ignored")
            focus = 0.0
        if not shaping_emits(kind, angle, softness, focus):
            raise StageError("shaping leaves no direction to emit in (cone angle, softness and "
                             "focus together)", path,
                             "inputs:shaping:focus" if focus > 0.0 else "inputs:shaping:cone:angle")
        return angle, softness, focus

    def _warn(self, message: str) -> None:
        self.warnings.setdefault(message, None)


# --------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------

def _timecode(time) -> Usd.TimeCode:
    if time is None:
        return Usd.TimeCode.Default()
    if isinstance(time, Usd.TimeCode):
        return time
    return Usd.TimeCode(float(time))


_NAMESPACE = re.compile(r"pxrInternal_v\d+_\d+(?:_\d+)?__pxrReserved__::")
#: The session layer USD adds to layer stacks in messages: ",@anon:0x...:NAME-session.usda@".
_ANON_LAYER = re.compile(r",@anon:[^@]*@")

#: Composition errors that leave the luminaire incomplete or undefined, with what to say.
_FATAL_COMPOSITION = {
    Pcp.ErrorType_InvalidAssetPath: "cannot open a referenced layer",
    Pcp.ErrorType_InvalidSublayerPath: "cannot open a sublayer",
    Pcp.ErrorType_ArcCycle: "composition cycle",
    Pcp.ErrorType_SublayerCycle: "sublayer cycle",
    Pcp.ErrorType_UnresolvedPrimPath: "reference to a prim that does not exist",
    Pcp.ErrorType_InvalidPrimPath: "reference to an invalid prim path",
    Pcp.ErrorType_ArcCapacityExceeded: "composition too deep",
    Pcp.ErrorType_ArcNamespaceDepthCapacityExceeded: "composition too deep",
    Pcp.ErrorType_IndexCapacityExceeded: "composition too large",
}
_SUBLAYER_ERRORS = {Pcp.ErrorType_InvalidSublayerPath, Pcp.ErrorType_SublayerCycle,
                    Pcp.ErrorType_InvalidSublayerOffset,
                    Pcp.ErrorType_InvalidSublayerOwnership}


def _arc_property(message: str) -> str:
    """The composition arc a Pcp message is about, as the metadata field that authors it."""
    text = message.lower()
    for word, field_name in (("payload", "payload"), ("inherit", "inherits"),
                             ("specializ", "specializes"), ("variant", "variantSets")):
        if word in text:
            return field_name
    return "references"


def _tf_message(error) -> str:
    """The readable part of a pxr error (Tf.ErrorException or a composition error)."""
    text = _NAMESPACE.sub("", str(error)).strip()
    messages = []
    for chunk in re.split(r"\s*Error in ", text):
        _, sep, body = chunk.partition(" : '")
        if sep:
            messages.append(body.strip().rstrip("'"))
    message = messages[0] if messages else text or repr(error)
    # parser internals between "parse error" and the offending text
    message = re.sub(r" matching .*? at '", " at '", message, flags=re.DOTALL)
    return " ".join(message.split())[:300]


def _light_kind(prim: Usd.Prim) -> str | None:
    for light_type, kind in _LIGHT_TYPES:
        if prim.IsA(light_type):
            return kind
    return None


def _array(value, where: str, prop: str, dtype=np.float64, width: int | None = None
           ) -> np.ndarray:
    """An array attribute's value as a numpy array ((N,) or (N, width)); no value gives an
    empty one. A value of another type (an unknown type name in the file, text) is a
    StageError naming the prim and property."""
    if value is None:
        return np.zeros((0, width) if width else 0, dtype=dtype)
    try:
        arr = np.asarray(value, dtype=dtype)
        arr = arr.reshape(-1, width) if width else arr.reshape(-1)
        if not width and np.ndim(value) != 1:
            raise ValueError(value)
    except (TypeError, ValueError, OverflowError):
        kind = f"{width}-component vectors" if width else "numbers"
        raise StageError(f"expected an array of {kind}, got {type(value).__name__}",
                         where, prop) from None
    return arr


def _has_api(prim: Usd.Prim, name: str) -> bool:
    """Whether the API schema ``name`` is applied to ``prim``, also when USD does not know
    the schema (its plugin was registered too late): then ``apiSchemas`` still lists it."""
    return prim.HasAPI(name) or name in prim.GetPrimTypeInfo().GetAppliedAPISchemas()


def _material_api_values(prim: Usd.Prim, time: Usd.TimeCode) -> dict[str, Sourced]:
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


def _triangulate(points: np.ndarray, counts: np.ndarray, indices: np.ndarray,
                 keep_face: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate polygons: (T, 3, 3) triangles and the face each one came from."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    per_face = np.where(keep_face, np.maximum(counts - 2, 0), 0)
    face = np.repeat(np.arange(counts.size), per_face)
    k = np.arange(face.size) - np.repeat(np.cumsum(per_face) - per_face, per_face)
    first = starts[face]
    corners = np.stack([indices[first], indices[first + k + 1], indices[first + k + 2]],
                       axis=1)
    return points[corners], face


def _closed_surface_volume(triangles: np.ndarray) -> tuple[bool, float]:
    """Whether triangles (T, 3, 3) form closed, consistently wound surfaces, and their
    signed volume (positive when the counter-clockwise fronts face outward).

    Corners are matched by position (exports often split vertices along seams). Closed and
    consistent: every directed edge occurs exactly once, and so does its reverse; triangles
    with a repeated corner have no area and are ignored.
    """
    corners = np.ascontiguousarray(triangles.reshape(-1, 3), dtype=np.float64) + 0.0  # -0 -> 0
    keys = corners.view(np.dtype((np.void, corners.dtype.itemsize * 3))).ravel()
    _, vertex = np.unique(keys, return_inverse=True)
    vertex = vertex.reshape(-1, 3).astype(np.int64)
    a, b, c = vertex.T
    proper = (a != b) & (b != c) & (c != a)
    a, b, c = a[proper], b[proper], c[proper]
    if a.size == 0:
        return False, 0.0
    n = int(vertex.max()) + 1
    edges = np.concatenate([a * n + b, b * n + c, c * n + a])
    reverse = np.concatenate([b * n + a, c * n + b, a * n + c])
    edges.sort()
    reverse.sort()
    closed = bool(np.all(edges[1:] != edges[:-1]) and np.array_equal(edges, reverse))
    tri = triangles[proper] - corners.mean(axis=0)
    volume = float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()) / 6.0
    return closed, volume


def _invertible(linear: np.ndarray) -> bool:
    """Whether a 3x3 map is far from singular (condition number below 1e12)."""
    sv = np.linalg.svd(np.asarray(linear, dtype=np.float64), compute_uv=False)
    return bool(sv[0] > 0.0 and sv[-1] > 1e-12 * sv[0])


def _non_degenerate(triangles: np.ndarray) -> np.ndarray:
    """Mask of triangles with a non-zero area (relative to their longest edge), at any
    scale: edges are scaled by a power of two to a largest coordinate near 1 before squaring,
    so that triangles of 1e-200 m do not underflow nor those of 1e200 m overflow."""
    e1 = triangles[:, 1] - triangles[:, 0]
    e2 = triangles[:, 2] - triangles[:, 0]
    size = np.maximum(np.abs(e1).max(axis=1), np.abs(e2).max(axis=1))
    ok = (size > 0.0) & np.isfinite(size)
    _, exponent = np.frexp(np.where(ok, size, 1.0))
    e1 = np.ldexp(np.where(ok[:, None], e1, 0.0), -exponent[:, None])  # exact powers of 2
    e2 = np.ldexp(np.where(ok[:, None], e2, 0.0), -exponent[:, None])
    e3 = e2 - e1
    cross = np.linalg.norm(np.cross(e1, e2), axis=1)
    longest = np.max(np.stack([np.einsum("ij,ij->i", e, e) for e in (e1, e2, e3)]), axis=0)
    return ok & (cross > DEGENERATE_TOLERANCE * longest)


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


def _axis_permutation(axis: str) -> list[int]:
    """Column order mapping shapes built along +Z onto ``axis`` (a rotation, so
    right-handedness is kept)."""
    return {"X": [2, 0, 1], "Y": [1, 2, 0], "Z": [0, 1, 2]}[axis]


def _implicit_polygons(prim: Usd.Prim, time: Usd.TimeCode):
    """Points, face counts, indices and kept faces of an implicit gprim, outward faces CCW."""
    path = str(prim.GetPath())
    type_name = str(prim.GetTypeName())
    n = TESSELLATION_SEGMENTS
    phi = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    ring = np.arange(n)
    nxt = (ring + 1) % n
    if type_name == "Cube":
        size = validate.check_positive(UsdGeom.Cube(prim).GetSizeAttr().Get(time), path, "size")
        h = 0.5 * size
        points = np.array([[x, y, z] for z in (-h, h) for y in (-h, h) for x in (-h, h)])
        quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2],
                 [1, 3, 7, 5]]
        return _polygons(points, quads)
    if type_name == "Sphere":
        r = validate.check_positive(UsdGeom.Sphere(prim).GetRadiusAttr().Get(time), path,
                                    "radius")
        rings = TESSELLATION_RINGS
        theta = np.linspace(0.0, math.pi, rings + 1)[1:-1]
        grid = np.stack([np.outer(np.sin(theta), np.cos(phi)),
                         np.outer(np.sin(theta), np.sin(phi)),
                         np.outer(np.cos(theta), np.ones(n))], axis=-1).reshape(-1, 3)
        points = r * np.vstack([[0.0, 0.0, 1.0], grid, [0.0, 0.0, -1.0]])
        south = len(points) - 1
        faces = [[0, 1 + i, 1 + j] for i, j in zip(ring, nxt)]
        for band in range(rings - 2):
            a, b = 1 + band * n, 1 + (band + 1) * n
            faces += [[a + i, b + i, b + j, a + j] for i, j in zip(ring, nxt)]
        last = 1 + (rings - 2) * n
        faces += [[south, last + j, last + i] for i, j in zip(ring, nxt)]
        return _polygons(points, faces)
    if type_name in ("Cylinder", "Cone"):
        schema_ = UsdGeom.Cylinder(prim) if type_name == "Cylinder" else UsdGeom.Cone(prim)
        r = validate.check_positive(schema_.GetRadiusAttr().Get(time), path, "radius")
        height = validate.check_positive(schema_.GetHeightAttr().Get(time), path, "height")
        axis = validate.check_token(schema_.GetAxisAttr().Get(time), _AXES, path, "axis")
        circle = np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
        bottom = np.column_stack([circle, np.full(n, -0.5 * height)])
        if type_name == "Cylinder":
            top = np.column_stack([circle, np.full(n, 0.5 * height)])
            points = np.vstack([bottom, top])
            faces = [[i, j, n + j, n + i] for i, j in zip(ring, nxt)]
            faces += [list(n + ring), list(ring[::-1])]
        else:
            points = np.vstack([bottom, [[0.0, 0.0, 0.5 * height]]])
            faces = [[i, j, n] for i, j in zip(ring, nxt)]
            faces += [list(ring[::-1])]
        return _polygons(points[:, _axis_permutation(axis)], faces)
    # Plane: a rectangle facing +axis
    plane = UsdGeom.Plane(prim)
    width = validate.check_positive(plane.GetWidthAttr().Get(time), path, "width")
    length = validate.check_positive(plane.GetLengthAttr().Get(time), path, "length")
    axis = validate.check_token(plane.GetAxisAttr().Get(time), _AXES, path, "axis")
    # UsdGeomPlane: width along x (z when axis is X), length along y (z when axis is Y).
    w, l = 0.5 * width, 0.5 * length
    corners = {"X": [[0, -l, -w], [0, l, -w], [0, l, w], [0, -l, w]],
               "Y": [[-w, 0, -l], [w, 0, -l], [w, 0, l], [-w, 0, l]],
               "Z": [[-w, -l, 0], [w, -l, 0], [w, l, 0], [-w, l, 0]]}[axis]
    points = np.asarray(corners, dtype=np.float64)
    normal = np.cross(points[1] - points[0], points[2] - points[0])
    face = [0, 1, 2, 3] if normal["XYZ".index(axis)] > 0 else [0, 3, 2, 1]
    return _polygons(points, [face])


def _polygons(points, faces):
    counts = np.array([len(f) for f in faces], dtype=np.int64)
    indices = np.concatenate([np.asarray(f, dtype=np.int64) for f in faces])
    return np.asarray(points, dtype=np.float64), counts, indices, np.ones(counts.size, bool)
