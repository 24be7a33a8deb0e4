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
  A light's flux, and the luminaire's, may be at most
  :data:`~lumitrace.stage.validate.MAX_LUMINOUS_FLUX`.
- **One time code** for every value: the caller's, else Default for a static luminaire,
  else the stage's ``startTimeCode`` or the earliest time sample, with a warning (see
  :mod:`lumitrace.stage.timing`); ``Scene.time_code`` records it.
- **Never lumitrace's own output.** A ``photometric`` selection of the
  ``lumitraceRepresentation`` variant set is read as ``geometry``, and a light
  ``lumitracePhotometricLight`` under the luminaire is skipped, each with a warning (see
  :mod:`lumitrace.stage.representation`).

Every bad value raises :class:`~lumitrace.errors.StageError` naming prim and property
(the rules live in :mod:`lumitrace.stage.validate`); imperfect but traceable input only
adds to ``Scene.warnings``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Usd

from .. import schema

schema.build_registry_soon()  # on a thread of its own while the schema modules load
from pxr import Sdf, Tf, UsdGeom, UsdLux  # noqa: E402
from ..errors import StageError
from ..scene import Emitter, LuminaireInfo, PartFrame, Scene
from ..scene.groups import group_emitters
from . import validate
from .diagnostics import UsdDiagnostics, check_composition, check_sublayers, tf_message
from .geometry import LocalMesh, local_mesh, non_degenerate
from .luminaire_data import LUMINAIRE_DATA, luminaire_data_problem
from .lights import body_triangles, has_body, light_kind, read_light, read_mesh_light
from .profile import has_profile, mesh_agrees, read_profile
from .materials import BoundMaterials
from .reuse import ReadCache
from .representation import is_stand_in_light, modelled_luminaire
from .timing import read_time, requested_time, scene_time_code
from .transforms import Frame, placements
from .validate import check_array

_RENDERED_PURPOSES = (UsdGeom.Tokens.default_, UsdGeom.Tokens.render)
_PURPOSES = (UsdGeom.Tokens.default_, UsdGeom.Tokens.render, UsdGeom.Tokens.proxy,
             UsdGeom.Tokens.guide)
_VISIBILITIES = (UsdGeom.Tokens.inherited, UsdGeom.Tokens.invisible)


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
        Time to read every value at; default: ``Usd.TimeCode.Default()`` for a static
        luminaire, else the stage's ``startTimeCode`` or the earliest time sample (see
        :mod:`lumitrace.stage.timing`). ``Scene.time_code`` records the one used.

    Raises
    ------
    StageError
        The file is missing or not a USD stage, or the stage has no luminaire, no emitter
        or a bad value; the message names the file or the prim and property.
    """
    return read_stage_file(path, luminaire, time=time)[0]


def read_stage_file(path: str | Path, luminaire: str | None = None, *,
                    time: Usd.TimeCode | float | None = None) -> tuple[Scene, bool]:
    """:func:`read_stage`, and whether the stage composed whole: no layer, reference or
    payload it names is missing or refused (a scene read without one depends on a
    file's absence too)."""
    file = Path(path)
    if not file.exists():
        raise StageError("stage file not found", str(file))
    if file.is_dir():
        raise StageError("is a folder, not a USD stage file", str(file))
    if not file.is_file():  # a FIFO or a device would be waited on, not read
        raise StageError("is not a regular file, not a USD stage file", str(file))
    file = file.resolve()
    validate.check_layer_file(file)
    with UsdDiagnostics() as diagnostics:
        try:
            stage = Usd.Stage.Open(str(file), Usd.Stage.LoadAll)
        except Tf.ErrorException as exc:
            raise StageError(f"cannot open as a USD stage: {tf_message(exc)}",
                             str(file)) from exc
        if stage is None:
            raise StageError("cannot open as a USD stage", str(file))
        scene = _read(stage, luminaire, time, diagnostics)
        return scene, not stage.GetCompositionErrors()


def scene_from_stage(stage: Usd.Stage, luminaire: str | None = None, *,
                     time: Usd.TimeCode | float | None = None,
                     cache: ReadCache | None = None) -> Scene:
    """Read the luminaire of an open stage into a :class:`Scene` (see :func:`read_stage`).

    The stage's composed state is read as it is, unsaved edits included. ``cache``: what
    the last read of it made, taken again where it is made of the same (a stage read
    after every edit, :class:`~lumitrace.stage.reuse.ReadCache`).
    """
    with UsdDiagnostics() as diagnostics:
        return _read(stage, luminaire, time, diagnostics, cache)


def _read(stage: Usd.Stage, luminaire: str | None, time, diagnostics: UsdDiagnostics,
          cache: ReadCache | None = None) -> Scene:
    layer = stage.GetRootLayer()
    stage_file = str(Path(layer.realPath).resolve()) if layer.realPath else ""
    label = stage_file or layer.identifier
    try:
        # every value read is checked explicitly: numpy's warnings about the NaN, Inf or
        # overflow those checks catch would only add lines to the one error a user sees
        with np.errstate(all="ignore"):
            return _Reader(stage, requested_time(time), stage_file, label,
                           diagnostics, cache).read(luminaire)
    except Tf.ErrorException as exc:
        raise StageError(f"USD error while reading the stage: {tf_message(exc)}",
                         label) from exc


# --------------------------------------------------------------------------------------
# The reader
# --------------------------------------------------------------------------------------

class _Reader:
    def __init__(self, stage: Usd.Stage, time: Usd.TimeCode | None, stage_file: str,
                 label: str, diagnostics: UsdDiagnostics, cache: ReadCache | None = None):
        self.stage = stage
        self.cache = cache
        self.diagnostics = diagnostics
        self.requested_time = time  # None: chosen by read_time
        self.root_path = Sdf.Path.emptyPath
        self.time = Usd.TimeCode.Default()
        self.stage_file = stage_file
        self.label = label
        self.xf = UsdGeom.XformCache(self.time)
        self.triangles: list[np.ndarray] = []
        self.material_index: list[np.ndarray] = []
        self.part_index: list[np.ndarray] = []
        self.parts: dict[str, int] = {}
        self.materials = BoundMaterials(self.time, self._warn)
        self.emitters: list[Emitter] = []
        self.warnings: dict[str, None] = {}
        self.local_meshes: dict[str, LocalMesh | None] = {}
        #: per part, its triangles in its own space and the one placement that puts them in
        #: the world (None for a part placed more than once, or a light's body)
        self.part_frames: dict[int, PartFrame | None] = {}
        self.meters_per_unit = 1.0
        self.up_axis = "Z"

    # -- top level ----------------------------------------------------------------------

    def read(self, luminaire: str | None) -> Scene:
        # a sublayer that cannot be opened explains a missing luminaire: say that first
        check_sublayers(self.stage, self.stage_file or self.label)
        root = self._luminaire_prim(luminaire)
        # our own photometric stand-in is never traced: read the modelled luminaire
        with modelled_luminaire(self.stage, root, self._warn) as stage:
            self.stage = stage
            root = stage.GetPrimAtPath(root.GetPath())
            # one time code for every value read
            self.time = read_time(stage, root, self.requested_time, self._warn)
            self.xf = UsdGeom.XformCache(self.time)
            self.materials = BoundMaterials(self.time, self._warn)
            return self._read_luminaire(root)

    def _read_luminaire(self, root: Usd.Prim) -> Scene:
        root_path = str(root.GetPath())
        self.root_path = root.GetPath()
        layer_where = self.stage_file or self.label
        if not UsdGeom.StageHasAuthoredMetersPerUnit(self.stage):
            self._warn(f"{layer_where}: metersPerUnit is not authored: assuming centimetres "
                       "(USD's fallback, 0.01 m per unit)")
        self.meters_per_unit = float(UsdGeom.GetStageMetersPerUnit(self.stage))
        validate.check_stage_units(self.meters_per_unit, layer_where)
        up_axis = str(UsdGeom.GetStageUpAxis(self.stage))
        validate.check_up_axis(up_axis, layer_where)
        self.up_axis = up_axis
        check_composition(self.stage, root, layer_where, self._warn)

        if self._visible_and_rendered(root, computed=True):
            self._walk(root, Frame())
        unbound = self.materials.unbound
        if unbound:
            example = unbound[0]
            more = f" and {len(unbound) - 1} more" if len(unbound) > 1 else ""
            self._warn(f"{example}{more}: no material bound: using diffuse reflectance "
                       f"{schema.MATERIAL_FALLBACKS[schema.REFLECTANCE]:g}")
        if not self.emitters:
            raise StageError("no emitter: the luminaire has no active, visible Sphere, Disk, "
                             f"Rect or Cylinder light or mesh light (in {self.label})", root_path)
        validate.check_total_flux([e.flux for e in self.emitters], root_path)

        for note in self.diagnostics.take():
            self._warn(f"{self.label}: USD: {note}")
        if self.cache is not None:
            self.cache.keep_only(set(self.local_meshes))
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
            materials=tuple(self.materials.materials),
            parts=tuple(self.parts),
            part_frames=tuple(self.part_frames.get(i) for i in range(len(self.parts))),
            emitters=group_emitters(self.emitters),
            up_axis=up_axis,
            meters_per_unit=self.meters_per_unit,
            luminaire_path=root_path,
            stage_path=self.stage_file,
            warnings=tuple(self.warnings),
            time_code=scene_time_code(self.time),
            luminaire_to_world=self._luminaire_to_world(root),
            layer_files=tuple(sorted(layer.realPath for layer in self.stage.GetUsedLayers()
                                     if layer.realPath)),  # (USD's order is a set's)
            info=self._luminaire_info(root),
            declared_symmetry=self._declared_symmetry(root),
            declared_opening=self._declared_opening(root),
        )

    def _authored(self, prim: Usd.Prim, name: str):
        """An attribute's authored value at the reading time, or None."""
        attr = prim.GetAttribute(name)
        return attr.Get(self.time) if attr and attr.HasAuthoredValue() else None

    def _declared_symmetry(self, root: Usd.Prim) -> str:
        """The symmetry declared on the luminaire prim ("" where none is: auto)."""
        value = self._authored(root, schema.SYMMETRY)
        if value is None:
            return ""
        value = validate.check_token(value, schema.SYMMETRY_TOKENS, str(root.GetPath()),
                                     schema.SYMMETRY)
        return "" if value == "auto" else value

    def _declared_opening(self, root: Usd.Prim) -> tuple:
        """A declared luminous opening: (shape, (length, width, height) in m), or ()."""
        where = str(root.GetPath())
        shape = self._authored(root, schema.OPENING_SHAPE)
        size = self._authored(root, schema.OPENING_SIZE)
        if shape is not None:
            shape = validate.check_token(shape, schema.OPENING_SHAPES, where,
                                         schema.OPENING_SHAPE)
        if shape in (None, "measured"):
            return ()
        if size is None:
            raise StageError(f"{schema.OPENING_SHAPE} is {shape!r}: author its size "
                             "(length, width, height in stage units)", where,
                             schema.OPENING_SIZE)
        values = validate.check_array(size, where, schema.OPENING_SIZE)
        if values.shape != (3,) or not np.all(np.isfinite(values)) or np.any(values < 0) \
                or np.any(values[:2] <= 0):
            raise StageError("must be (length, width, height), length and width above 0 "
                             f"and height at least 0, got {tuple(values.tolist())}", where,
                             schema.OPENING_SIZE)
        if shape == "round" and values[0] != values[1]:
            raise StageError("a round opening has one diameter: length and width must be "
                             f"equal, got {values[0]:g} and {values[1]:g}", where,
                             schema.OPENING_SIZE)
        return shape, tuple(float(v) * self.meters_per_unit for v in values)

    def _luminaire_info(self, root: Usd.Prim) -> LuminaireInfo:
        """The luminaire's own data (manufacturer, names, lamp, power, colour rendering),
        checked as :mod:`.luminaire_data` says: one line of printable text, the power
        finite and at least 0, the colour rendering index finite in [0, 100]."""
        where = str(root.GetPath())
        values = {}
        for name in LUMINAIRE_DATA:
            attr = root.GetAttribute(name)
            value = attr.Get(self.time) if attr and attr.HasAuthoredValue() else None
            if value is None:
                continue
            problem = luminaire_data_problem(name, value)
            if problem is not None:
                raise StageError(problem, where, name)
            values[name] = value.strip() if isinstance(value, str) else float(value)
        text = {name: values.get(name, "") for name in schema.LUMINAIRE_TEXT}
        return LuminaireInfo(text[schema.MANUFACTURER], text[schema.LUMINAIRE_NAME],
                             text[schema.CATALOGUE_NUMBER], text[schema.LAMP_DESCRIPTION],
                             values.get(schema.INPUT_POWER),
                             values.get(schema.COLOUR_RENDERING_INDEX))

    def _luminaire_to_world(self, root: Usd.Prim) -> tuple:
        """The luminaire prim's local-to-world transform (local stage units to world m),
        or () where it is the identity."""
        m = np.array(UsdGeom.XformCache(self.time).GetLocalToWorldTransform(root))
        if np.allclose(m, np.eye(4), rtol=0.0, atol=1e-12):
            return ()
        to_world = np.diag([self.meters_per_unit] * 3 + [1.0]) @ m.T
        return tuple(map(tuple, to_world.tolist()))

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

    def _walk(self, root: Usd.Prim, frame: Frame) -> None:
        if frame.anchor is None:
            predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
        else:  # prototypes may sit under an "over" or "class" to hide them from traversals
            predicate = Usd.TraverseInstanceProxies(Usd.PrimIsActive & Usd.PrimIsLoaded)
        it = iter(Usd.PrimRange(root, predicate))
        for prim in it:
            if not self._visible_and_rendered(prim, computed=False):
                it.PruneChildren()
                continue
            kind = light_kind(prim)
            if (kind is not None or prim.HasAPI(UsdLux.LightAPI)) \
                    and is_stand_in_light(prim, self.root_path):
                self._warn(f"{prim.GetPath()}: the stand-in light of lumitrace's photometric "
                           "representation (its own result) is not traced: skipped")
                it.PruneChildren()
                continue
            if kind is not None:
                emitters = read_light(prim, kind, frame, self.xf, self.meters_per_unit,
                                      self._warn)
                self.emitters.extend(emitters)
                if has_body(prim, self.time):
                    self._light_body(prim, kind, emitters)
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
                first = len(self.triangles)
                self._gprim(prim, frame)
                if prim.HasAPI(UsdLux.LightAPI):  # MeshLightAPI: the surface emits too
                    self.emitters.extend(read_mesh_light(
                        prim, self.triangles[first:], self.time, self._warn))

    def _visible_and_rendered(self, prim: Usd.Prim, computed: bool) -> bool:
        imageable = UsdGeom.Imageable(prim)
        if not imageable:
            return True
        path = str(prim.GetPath())
        visibility = validate.check_token(imageable.GetVisibilityAttr().Get(self.time),
                                          _VISIBILITIES, path, "visibility")
        validate.check_token(imageable.GetPurposeAttr().Get(self.time), _PURPOSES, path,
                             "purpose")
        if computed:
            visibility = imageable.ComputeVisibility(self.time)
        # else: ancestors were checked on the way down
        if visibility == UsdGeom.Tokens.invisible:
            return False
        return imageable.ComputePurpose() in _RENDERED_PURPOSES

    def _point_instancer(self, prim: Usd.Prim, frame: Frame) -> None:
        path = str(prim.GetPath())
        instancer = UsdGeom.PointInstancer(prim)
        prototypes = instancer.GetPrototypesRel().GetForwardedTargets()
        proto_indices = check_array(instancer.GetProtoIndicesAttr().Get(self.time), path,
                                    "protoIndices", np.int64)
        if proto_indices.size == 0:
            self._warn(f"{path}: point instancer has no instances")
            return
        for name, size in (("positions", 3), ("orientations", 4), ("orientationsf", 4),
                           ("scales", 3)):
            attr = prim.GetAttribute(name)
            arr = check_array(attr.Get(self.time) if attr else None, path, name, width=size)
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
        instancer_placements = placements(self.xf, prim, frame)
        for proto_number, target in enumerate(prototypes):
            proto = self.stage.GetPrimAtPath(target)
            if not proto:
                raise StageError(f"prototype {target} does not exist", path, "prototypes")
            chosen = np.flatnonzero((proto_indices == proto_number) & mask)
            if chosen.size == 0:
                continue
            bases = [(mats[i] @ world, f"{label}[{path}:{i}]")
                     for world, label in instancer_placements for i in chosen]
            self._walk(proto, Frame(proto, bases))

    def _gprim(self, prim: Usd.Prim, frame: Frame) -> None:
        """Place a gprim's triangles (read once, see :func:`.geometry.local_mesh`) in the
        world, at every placement of ``frame``."""
        path = str(prim.GetPath())
        if path not in self.local_meshes and has_profile(prim) and prim.IsA(UsdGeom.Mesh):
            self._check_profile(prim)
        if path not in self.local_meshes:
            self.local_meshes[path] = local_mesh(prim, self.time, self.materials, self._warn,
                                                 self.cache)
        local = self.local_meshes[path]
        if local is None or len(local.triangles) == 0:
            return
        part = self.parts.setdefault(path, len(self.parts))
        flat = local.triangles.reshape(-1, 3)
        where = placements(self.xf, prim, frame)
        for matrix, _ in where:

            def placed():
                world = (flat @ matrix[:3, :3] + matrix[3, :3]) * self.meters_per_unit
                world = world.reshape(-1, 3, 3)
                validate.check_extent(world, path, "points")
                flip = np.linalg.det(matrix[:3, :3]) < 0.0  # a mirror flips the winding
                if flip:
                    world = world[:, [0, 2, 1]]
                keep = non_degenerate(world)
                own = None  # the part's own triangles, for its frame (one placement)
                if len(where) == 1:
                    own = local.triangles[:, [0, 2, 1]] if flip else local.triangles
                    own = np.ascontiguousarray(own[keep], np.float32)
                return world[keep], keep, own

            if self.cache is not None and len(where) == 1:
                world, keep, own = self.cache.placed(path, local.triangles, matrix,
                                                     self.meters_per_unit, placed)
            else:
                world, keep, own = placed()
            dropped = int(keep.size - np.count_nonzero(keep))
            if dropped:
                self._warn(f"{path}: {dropped} zero-area triangle(s) dropped")
            self.triangles.append(world)
            self.material_index.append(local.material_index[keep])
            self.part_index.append(np.full(len(world), part, dtype=np.int32))
            self.part_frames[part] = None if part in self.part_frames or own is None else \
                PartFrame(own, matrix[:3, :3] * self.meters_per_unit,
                          matrix[3, :3] * self.meters_per_unit)

    def _check_profile(self, prim: Usd.Prim) -> None:
        """Validate a mesh's generating profile (a bad value is an error naming it) and
        warn where its points and faces are not the profile's: the mesh is traced as
        authored, which is what every DCC shows."""
        profile = read_profile(prim, self.time, self.up_axis)
        mesh = UsdGeom.Mesh(prim)
        path = str(prim.GetPath())
        points = check_array(mesh.GetPointsAttr().Get(self.time), path, "points", width=3)
        counts = check_array(mesh.GetFaceVertexCountsAttr().Get(self.time), path,
                             "faceVertexCounts", np.int64)
        indices = check_array(mesh.GetFaceVertexIndicesAttr().Get(self.time), path,
                              "faceVertexIndices", np.int64)
        if not mesh_agrees(profile, points, counts, indices):
            self._warn(f"{path}: its points and faces are not those of its profile "
                       "(lumitrace:profile:*): traced as authored; a scene delta or a fit "
                       "that changes the profile writes them anew")

    def _light_body(self, prim: Usd.Prim, kind: str, emitters: list[Emitter]) -> None:
        """The light's own surface as a part of the material bound to the light, at each of
        its placements (``lumitrace:body``)."""
        e = emitters[0] if emitters else None
        if e is None or (kind == "sphere" and (e.treat_as_point or e.radius == 0.0)):
            self._warn(f"{prim.GetPath()}.{schema.BODY}: a point light has no body: ignored")
            return
        dims = {"radius": e.radius, "width": e.width, "height": e.height, "length": e.length}
        local = body_triangles(kind, dims).reshape(-1, 3)
        material = self.materials.material_for(prim, prim)
        part = self.parts.setdefault(str(prim.GetPath()), len(self.parts))
        for em in emitters:
            m = np.asarray(em.to_world, np.float64)  # local units to world m
            world = (local @ m[:3, :3].T + m[:3, 3]).reshape(-1, 3, 3)
            if np.linalg.det(m[:3, :3]) < 0.0:
                world = world[:, [0, 2, 1]]
            self.triangles.append(world)
            self.material_index.append(np.full(len(world), material, np.int32))
            self.part_index.append(np.full(len(world), part, np.int32))

    def _warn(self, message: str) -> None:
        self.warnings.setdefault(message, None)
