"""The flat scene the tracer works on: triangles, materials and emitters as numpy arrays.

Everything here is in SI units (metres, lumens) and in the stage's own world axes; the
stage reader builds it, the tracer only reads it. Arrays are plain numpy so the scene can
be hashed, pickled to workers and compared.
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field, fields

import numpy as np

#: Scattering models, in the order of their integer codes in :attr:`Materials.kind`.
SCATTERING_MODELS = ("diffuse", "mirror", "glossy", "translucent", "dielectric", "absorber")
DIFFUSE, MIRROR, GLOSSY, TRANSLUCENT, DIELECTRIC, ABSORBER = range(len(SCATTERING_MODELS))

#: UsdLux light types we emit from, in the order of their codes in :attr:`Emitter.kind`.
EMITTER_KINDS = ("sphere", "disk", "rect", "cylinder", "mesh")


def point_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The smallest and largest coordinate (3,) of ``points`` (N, 3): a column at a time
    (numpy reduces the rows of an (N, 3) array seven times slower; 17 ms at 250k
    triangles' corners)."""
    pts = np.asarray(points).reshape(-1, 3)
    return (np.array([pts[:, k].min() for k in range(3)]),
            np.array([pts[:, k].max() for k in range(3)]))


@dataclass(frozen=True)
class Material:
    """Photometric surface properties of one material (all fractions in [0, 1]).

    ``reflectance`` is the diffuse (Lambertian) reflectance, ``specular_reflectance`` the
    mirror/glossy albedo, ``transmittance`` the diffuse transmittance of a translucent
    material (dielectrics are clear and do not use it), ``ior`` the refractive index of a
    dielectric (outside is air, n = 1), ``roughness`` the GGX
    roughness (alpha = roughness**2) of a glossy one.
    """

    path: str
    scattering: str = "diffuse"
    reflectance: float = 0.8
    specular_reflectance: float = 1.0
    transmittance: float = 0.0
    ior: float = 1.5
    roughness: float = 0.2
    #: spectral values on :data:`lumitrace.scene.spectra.WAVELENGTHS` of the diffuse
    #: reflectance, the specular reflectance and the transmittance; () where the scalar
    #: above holds at every wavelength (a neutral surface)
    reflectance_spectrum: tuple = ()
    specular_spectrum: tuple = ()
    transmittance_spectrum: tuple = ()
    #: a dielectric's Abbe number (0: no dispersion; ``ior`` holds at every wavelength), or
    #: its Sellmeier coefficients (B1, B2, B3, C1, C2, C3; C in square micrometres), which
    #: then give its index at every wavelength
    abbe_number: float = 0.0
    sellmeier: tuple = ()

    @property
    def kind(self) -> int:
        return SCATTERING_MODELS.index(self.scattering)

    @property
    def neutral(self) -> bool:
        """Whether the surface treats every wavelength alike (no spectral work needed)."""
        return not (self.reflectance_spectrum or self.specular_spectrum
                    or self.transmittance_spectrum or self.dispersive)

    @property
    def dispersive(self) -> bool:
        """Whether the refractive index depends on the wavelength."""
        return bool(self.abbe_number or self.sellmeier)

    def spectrum(self, name: str) -> np.ndarray:
        """A property (``reflectance``, ``specular``, ``transmittance`` or ``ior``) at
        every grid wavelength, (401,)."""
        from .spectra import WAVELENGTHS, cauchy_ior, sellmeier_ior

        if name == "ior":
            if self.sellmeier:
                return sellmeier_ior(self.sellmeier)
            return (cauchy_ior(self.ior, self.abbe_number) if self.abbe_number
                    else np.full(WAVELENGTHS.size, self.ior))
        values = {"reflectance": (self.reflectance_spectrum, self.reflectance),
                  "specular": (self.specular_spectrum, self.specular_reflectance),
                  "transmittance": (self.transmittance_spectrum, self.transmittance)}[name]
        return (np.asarray(values[0], np.float64) if values[0]
                else np.full(WAVELENGTHS.size, values[1]))


#: Unit vector of each stage up axis.
UP_VECTORS = {"Z": (0.0, 0.0, 1.0), "Y": (0.0, 1.0, 0.0)}


def photometric_axes(up_axis: str, rotation=()) -> np.ndarray:
    """Rows (C0, C90, up) of type C photometry's frame in world axes: up is the luminaire's
    own up (the stage's up axis turned by ``rotation``, the luminaire prim's 3x3 world
    rotation, none by default), C0 its +X made perpendicular to up, C90 = up x C0 (C grows
    counter-clockwise seen from above); nadir, gamma 0, is -up."""
    r = np.asarray(rotation, np.float64) if len(rotation) else np.eye(3)
    up = r @ np.asarray(UP_VECTORS[up_axis])
    up = up / np.linalg.norm(up)
    c0 = r @ np.array([1.0, 0.0, 0.0])
    c0 = c0 - (c0 @ up) * up
    c0 = c0 / np.linalg.norm(c0)
    return np.stack([c0, np.cross(up, c0), up])


@dataclass(frozen=True)
class IesShaping:
    """A measured intensity profile shaping a light (UsdLuxShapingAPI ``shaping:ies:*``):
    the file (IES LM-63, or EULUMDAT by its ``.ldt`` extension; absolute path), its
    ``angleScale`` and ``normalize``. The profile is the light's far-field intensity
    distribution in its own frame: gamma 0 along local -Z, C 0 toward local +X, C 90
    toward local +Y; the light's shape only places the photons' start points."""

    file: str
    angle_scale: float = 0.0
    normalize: bool = False
    stamp: str = ""  # the file's size and modification time when read: a new file, a new light


@dataclass(frozen=True, eq=False)
class LightGroup:
    """The lights an emitter stands for when it is a group of identical lights that differ
    only in place and flux (an LED board): each light's prim path, its offset (M, 3; world
    m) from the group's transform and its share (M,) of the group's flux. The group emits
    as their flux-weighted mixture: each photon comes from one light, drawn by share."""

    paths: tuple[str, ...]
    offsets: np.ndarray
    shares: np.ndarray

    def __len__(self) -> int:
        return len(self.paths)

    def __eq__(self, other) -> bool:
        return isinstance(other, LightGroup) and self.paths == other.paths and \
            np.array_equal(self.offsets, other.offsets) and \
            np.array_equal(self.shares, other.shares)

    def __hash__(self) -> int:
        return hash(self.paths)


@dataclass(frozen=True)
class Emitter:
    """One UsdLux light as a Lambertian emitter of known flux.

    ``to_world`` (4x4, column-vector convention: ``p_world = M[:3,:3] @ p + M[:3,3]``) maps
    the light's local space, in stage units, to world metres. Shape sizes are in local stage
    units, as authored. One-sided area lights (disk, rect) emit towards their local -Z, as
    UsdLux defines; sphere and cylinder lights emit outward from their surface; a mesh
    light (UsdLux MeshLightAPI on a gprim) from the front of its ``triangles``, or both
    sides.
    ``cone_angle`` (degrees; 180, or 90 for one-sided lights, means unshaped), ``cone_softness`` and ``focus`` come from
    UsdLuxShapingAPI, measured from the emission axis (-Z); see :mod:`lumitrace.trace.emission`.
    """

    path: str
    kind: str
    flux: float
    to_world: np.ndarray
    radius: float = 0.5
    width: float = 1.0
    height: float = 1.0
    length: float = 1.0
    treat_as_point: bool = False
    cone_angle: float = 180.0
    cone_softness: float = 0.0
    focus: float = 0.0
    ies: IesShaping | None = None
    #: a mesh light's triangles (T, 3, 3), world metres less ``to_world``'s translation
    #: (their centre), front faces counter-clockwise; it emits from both sides if two-sided
    triangles: np.ndarray | None = None
    two_sided: bool = False
    #: a TM-25 ray file (absolute path) whose rays the light emits, in its own frame, and
    #: the light's local units per millimetre (the file's unit)
    rays: str | None = None
    ray_scale: float = 1.0
    rays_stamp: str = ""  # the ray file's size and modification time when read
    ray_extent: tuple = ()  # half extents (3,) of the rays' start points, local units
    #: relative spectral power on :data:`lumitrace.scene.spectra.WAVELENGTHS` (401,);
    #: () when the stage gives the light no colour (white)
    spectrum: tuple = ()
    #: a ray file with a wavelength per ray: each photon starts with its ray's colour
    ray_bands: bool = False
    #: the lights this emitter stands for, when it is a group of them (None: one light);
    #: ``to_world`` is then the first light's
    group: LightGroup | None = None

    @property
    def light_paths(self) -> tuple[str, ...]:
        """The prim paths of the lights this emitter stands for."""
        return self.group.paths if self.group is not None else (self.path,)

    def light_origins(self) -> np.ndarray:
        """World origins (M, 3; m) of the lights this emitter stands for."""
        origin = np.asarray(self.to_world, np.float64)[:3, 3]
        return origin + self.group.offsets if self.group is not None else origin[None]

    @property
    def key(self) -> int:
        """A stable 64-bit key from the prim path: keys the emitter's random stream, so
        adding or removing another emitter does not change this one's photons."""
        return int.from_bytes(hashlib.sha256(self.path.encode()).digest()[:8], "little")

    @property
    def reach(self) -> float:
        """Distance (local units) from the light's origin that its emitting surface reaches.

        Only the sizes of the light's own kind count: the others keep their dataclass
        defaults (1 stage unit), which would make a 1 mm LED modelled in metres a metre wide
        and the tracing frame, hence float rounding and ray offsets, depend on the unit.
        """
        if self.rays is not None:
            return float(np.linalg.norm(self.ray_extent))
        if self.kind == "sphere":
            return 0.0 if self.treat_as_point else self.radius  # a point has no surface
        if self.kind == "mesh":
            return float(np.linalg.norm(self.triangles.reshape(-1, 3), axis=1).max())
        if self.kind == "disk":
            return self.radius
        if self.kind == "rect":
            return 0.5 * float(np.hypot(self.width, self.height))
        return float(np.hypot(0.5 * self.length, self.radius))

    @property
    def half_extent(self) -> np.ndarray:
        """Half sizes (3,) of the emitting shape's box in the light's local axes (stage
        units): a disk or rect lies in its XY plane, a cylinder runs along X."""
        if self.rays is not None:
            return np.asarray(self.ray_extent, np.float64)
        if self.kind == "sphere":
            return np.full(3, 0.0 if self.treat_as_point else self.radius)
        if self.kind == "mesh":
            return np.abs(self.triangles.reshape(-1, 3)).max(axis=0)
        if self.kind == "disk":
            return np.array([self.radius, self.radius, 0.0])
        if self.kind == "rect":
            return np.array([0.5 * self.width, 0.5 * self.height, 0.0])
        return np.array([0.5 * self.length, self.radius, self.radius])

    def same_as(self, other: "Emitter", ignore: tuple[str, ...] = ()) -> bool:
        """Field-by-field equality (the transform is an array), ``ignore`` left out."""
        return all(np.array_equal(getattr(self, f.name), getattr(other, f.name))
                   for f in fields(self) if f.name not in ignore)


@dataclass(frozen=True)
class LuminaireInfo:
    """What the user says of the luminaire (LumitraceLuminaireAPI): written into the
    photometric files, never traced. Empty text and None where not authored."""

    manufacturer: str = ""
    name: str = ""
    catalogue_number: str = ""
    lamp: str = ""
    input_power_w: float | None = None
    colour_rendering_index: float | None = None


@dataclass(frozen=True, eq=False)
class PartFrame:
    """A part's triangles in its own space and the placement that puts them in the world:
    ``world = local @ linear + offset`` (row vectors, m); what lets a moved part be a new
    transform of the same structure, not new triangles."""

    local: np.ndarray   # (T, 3, 3) float32, the part's own units, in the scene's order
    linear: np.ndarray  # (3, 3) float64, own units to m
    offset: np.ndarray  # (3,) float64, m


@dataclass(frozen=True)
class Scene:
    """A luminaire as flat arrays, ready to trace.

    ``triangles`` is (T, 3, 3) float64 in world metres, front faces counter-clockwise
    (the reader flips left-handed meshes). ``material_index`` (T,) int32 indexes
    ``materials``; ``part_index`` (T,) int32 indexes ``parts`` (gprim paths), so results and
    errors can name the part a triangle came from.
    """

    triangles: np.ndarray
    material_index: np.ndarray
    part_index: np.ndarray
    materials: tuple[Material, ...]
    parts: tuple[str, ...]
    emitters: tuple[Emitter, ...]
    up_axis: str = "Z"
    meters_per_unit: float = 1.0
    luminaire_path: str = "/Luminaire"
    stage_path: str = ""
    warnings: tuple[str, ...] = field(default=(), compare=False)
    time_code: float | None = field(default=None, compare=False)  # None: default time
    #: the luminaire prim's local-to-world transform (4x4 rows, column-vector convention
    #: like :attr:`Emitter.to_world`: local stage units to world metres), which places the
    #: photometric frame and the stand-in light; empty: the identity
    luminaire_to_world: tuple = ()
    #: the files the stage was read from (its layers, real paths), which no output may
    #: replace; the emitters' IES and ray files are in :meth:`input_files`
    layer_files: tuple[str, ...] = field(default=(), compare=False)
    #: the luminaire's manufacturer, names, lamp, power and colour rendering
    info: LuminaireInfo = field(default_factory=LuminaireInfo, compare=False)
    #: per part, its own triangles and placement where it has one placement (else None;
    #: empty: none known): the same world triangles, as the tracer's structure takes them
    part_frames: tuple = field(default=(), compare=False, repr=False)
    #: the symmetry declared on the luminaire prim ("": none declared, lumitrace shows it)
    declared_symmetry: str = ""
    #: a declared luminous opening: (shape "rectangular" or "round", (length along C0,
    #: width along C90, height) in m); () where it is measured from the photons
    declared_opening: tuple = ()

    @property
    def photometric_axes(self) -> np.ndarray:
        """Rows (C0, C90, up) of the photometric frame in world axes (unit vectors)."""
        m = self.luminaire_to_world
        return photometric_axes(self.up_axis, np.asarray(m)[:3, :3] if len(m) else ())

    @property
    def colour(self) -> str:
        """How much colour work the scene needs: ``none`` (no light or surface has a
        colour: luminance only), ``emitters`` (coloured lights, neutral surfaces: each
        light's colour is the same in every direction, nothing is traced per wavelength)
        or ``spectral`` (a coloured or dispersive surface, or a ray file whose rays have
        wavelengths of their own: photons carry spectra)."""
        if any(not m.neutral for m in self.materials) or any(e.ray_bands
                                                             for e in self.emitters):
            return "spectral"
        return "emitters" if any(e.spectrum for e in self.emitters) else "none"

    @property
    def total_flux(self) -> float:
        """Luminous flux of all emitters together (lm)."""
        return float(sum(e.flux for e in self.emitters))

    def bound_points(self) -> np.ndarray:
        """Points (N, 3, world m) whose bounds hold the triangles and the emitters'
        surfaces (each light's reach as a cube around its origin)."""
        pts = [self.triangles.reshape(-1, 3)] if self.triangles.size else []
        cube = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0)
                         for z in (-1.0, 1.0)])
        if self.emitters:  # the transforms' 2-norms in one call (one each: 0.1 ms apiece)
            m = np.array([e.to_world for e in self.emitters], dtype=np.float64)
            size = np.linalg.norm(m[:, :3, :3], 2, axis=(1, 2))
            reach = np.array([e.reach for e in self.emitters], dtype=np.float64)
            pts += list(m[:, None, :3, 3] + (size * reach)[:, None, None] * cube)
            for e, r in zip(self.emitters, size * reach):  # every light of a group
                if e.group is not None:
                    pts.append((e.light_origins()[:, None, :] + r * cube).reshape(-1, 3))
        return np.concatenate(pts, axis=0) if pts else np.zeros((1, 3))

    def shape_points(self) -> np.ndarray:
        """Points (N, 3, world m) whose hull holds the triangles and the emitters' shapes:
        each light's local box corners carried by its transform (bounds in any frame)."""
        pts = [self.triangles.reshape(-1, 3)] if self.triangles.size else []
        signs = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0)
                          for z in (-1.0, 1.0)])
        for e in self.emitters:
            m = np.asarray(e.to_world, dtype=np.float64)
            box = (signs * e.half_extent) @ m[:3, :3].T
            pts.append((box[None] + e.light_origins()[:, None, :]).reshape(-1, 3))
        return np.concatenate(pts, axis=0) if pts else np.zeros((1, 3))

    def part_geometry(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Per part path: its triangles (T, 3, 3) and the path of each one's material."""
        mats = np.array([m.path for m in self.materials] or [""], dtype=object)
        out = {}
        for i, name in enumerate(self.parts):
            sel = self.part_index == i
            out[name] = (self.triangles[sel], mats[self.material_index[sel]]
                         if len(self.materials) else np.zeros(0, object))
        return out

    def input_files(self) -> set[str]:
        """Real paths of every file the scene was read from: the stage's layers and the
        emitters' IES profiles and ray files."""
        files = set(self.layer_files)
        for e in self.emitters:
            files.update(str(f) for f in (e.ies.file if e.ies is not None else None, e.rays)
                         if f)
        return {os.path.realpath(f) for f in files}

    def content_hash(self) -> str:
        """SHA-256 of everything the traced result depends on (geometry, materials,
        emitters, units), so a stored result can be recognised as stale."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.triangles, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(self.material_index, dtype=np.int32).tobytes())
        for m in self.materials:
            h.update(repr((m.scattering, m.reflectance, m.specular_reflectance,
                           m.transmittance, m.ior, m.roughness)).encode())
            if not m.neutral:
                h.update(repr((m.reflectance_spectrum, m.specular_spectrum,
                               m.transmittance_spectrum, m.abbe_number,
                               m.sellmeier)).encode())
        for e in self.emitters:
            h.update(repr((e.path, e.kind, e.flux, e.radius, e.width, e.height, e.length,
                           e.treat_as_point, e.cone_angle, e.cone_softness, e.focus)).encode())
            h.update(np.ascontiguousarray(e.to_world, dtype=np.float64).tobytes())
            if e.group is not None:
                h.update(repr(e.group.paths).encode())
                h.update(np.ascontiguousarray(e.group.offsets, np.float64).tobytes())
                h.update(np.ascontiguousarray(e.group.shares, np.float64).tobytes())
            if e.spectrum:
                h.update(np.asarray(e.spectrum, np.float64).tobytes())
            if e.triangles is not None:
                h.update(repr(e.two_sided).encode())
                h.update(np.ascontiguousarray(e.triangles, dtype=np.float64).tobytes())
            for f in ([e.ies.file] if e.ies is not None else []) + (
                    [e.rays] if e.rays is not None else []):
                h.update(repr((f, e.ies and (e.ies.angle_scale, e.ies.normalize),
                               e.ray_scale)).encode())
                try:
                    with open(f, "rb") as fh:
                        h.update(hashlib.sha256(fh.read()).digest())
                except OSError:
                    h.update(b"unreadable file")
        h.update(self.up_axis.encode())
        if self.declared_symmetry or self.declared_opening:  # they shape the files
            h.update(repr((self.declared_symmetry, self.declared_opening)).encode())
        if self.luminaire_to_world:
            h.update(np.asarray(self.photometric_axes, np.float64).tobytes())
        return h.hexdigest()
