"""Stress cases for the tracer and the stage reader, shared by ``tests/test_stress.py``
(small photon counts, in CI) and ``tools/stress.py`` (large counts, minutes).

Every case builds its stage with pxr in a scratch folder, traces or reads it, and returns a
:class:`CaseResult`: the measured outcome, the physically right answer it is held to, and
whether it holds. Tolerances are statistical (binomial standard errors) or exact
(photon bookkeeping is integer: escaped + absorbed + cut == photons).
"""
from __future__ import annotations

import dataclasses
import io
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)
from lumitrace.film.cubemap import texel_directions
from lumitrace.scene import Scene
from lumitrace.stage.reader import read_stage
from lumitrace.trace.tracer import MAX_DEPTH, BatchJob, prepare, trace_batch
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux

#: metersPerUnit of the units luminaires are modelled in.
UNITS = {"mm": 0.001, "cm": 0.01, "m": 1.0, "in": 0.0254}


# ------------------------------------------------------------------------------------------
# Results
# ------------------------------------------------------------------------------------------

@dataclass
class CaseResult:
    """What one stress case measured and whether it is right."""

    name: str
    ok: bool
    measured: str
    expected: str
    photons: int = 0
    seconds: float = 0.0
    details: dict = field(default_factory=dict)

    def __str__(self) -> str:
        return (f"{self.name}: {'ok' if self.ok else 'FAILED'}; measured {self.measured}; "
                f"expected {self.expected}")


@dataclass
class Traced:
    """Integer bookkeeping of a trace: photons per texel (6R, R) and the photons' fates,
    plus whether every traced ray was finite."""

    scene: Scene
    resolution: int
    photons: int
    counts: np.ndarray
    escaped: int
    absorbed: int
    cut: int
    segments: int
    finite: bool

    @property
    def balanced(self) -> bool:
        """Every photon escaped, was absorbed or was cut: exactly, as integers."""
        return self.escaped + self.absorbed + self.cut == self.photons

    def fractions(self) -> str:
        n = self.photons
        return (f"escaped {self.escaped / n:.6f}, absorbed {self.absorbed / n:.6f}, "
                f"cut {self.cut / n:.2e} of {n:,}")


def trace(scene: Scene, photons: int, resolution: int = 16, seed: int = 1,
          max_depth: int = MAX_DEPTH, batch: int = 1 << 16, check_rays: bool = True) -> Traced:
    """Trace ``photons`` photons of every emitter (split by flux, as a session does) in
    batches on this thread; with ``check_rays`` every traced ray is checked to be finite."""
    from lumitrace.run.session import allocate

    ps = prepare(scene)
    ntex = 6 * resolution * resolution
    counts = np.zeros((2, ntex), np.int64)
    absorbed = cut = segments = 0
    finite = True
    for e, share in enumerate(allocate([em.flux for em in scene.emitters], photons)):
        for start in range(0, share, batch):
            t = trace_batch(ps, BatchJob(e, start, min(batch, share - start), seed, resolution,
                                         max_depth), record_rays=check_rays)
            counts += t.counts
            absorbed += t.absorbed
            cut += t.cut
            segments += t.segments
            if check_rays:
                finite &= all(np.isfinite(o).all() and np.isfinite(d).all() for o, d in t.rays)
    c = counts.sum(axis=0)
    return Traced(scene, resolution, photons, c.reshape(6 * resolution, resolution),
                  int(c.sum()), absorbed, cut, segments, bool(finite))


def binomial_sigma(p: float, n: int) -> float:
    """Standard error of a fraction p estimated from n photons."""
    return math.sqrt(max(p * (1.0 - p), 0.0) / n)


# ------------------------------------------------------------------------------------------
# Stage building
# ------------------------------------------------------------------------------------------

def new_stage(path: Path, meters_per_unit: float = 1.0, up_axis: str = "Z",
              scale: float = 1.0, offset: Sequence[float] | None = None) -> Usd.Stage:
    """A stage with the default prim ``/Luminaire``; ``scale`` and ``offset`` (stage units)
    become double-precision xformOps on it."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    UsdGeom.SetStageUpAxis(stage, up_axis)
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    if offset is not None:
        root.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*offset))
    if scale != 1.0:
        root.AddScaleOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(scale, scale, scale))
    stage.SetDefaultPrim(root.GetPrim())
    return stage


def set_material(prim: Usd.Prim, scattering: str, **values: float) -> None:
    """Apply LumitraceMaterialAPI to a gprim with ``scattering`` and the given values
    (keyword names are the attribute names without ``lumitrace:``)."""
    prim.ApplyAPI("LumitraceMaterialAPI")
    prim.GetAttribute("lumitrace:scattering").Set(scattering)
    for name, value in values.items():
        prim.GetAttribute(f"lumitrace:{name}").Set(float(value))


def add_mesh(stage: Usd.Stage, path: str, points, faces, unit: float = 1.0,
             scattering: str | None = None, **material: float) -> UsdGeom.Mesh:
    """A mesh from points (metres, divided by ``unit`` = metersPerUnit) and faces (lists of
    point indices), with a material applied to the gprim when ``scattering`` is given."""
    pts = np.asarray(points, dtype=np.float64) / unit
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([Gf.Vec3f(*map(float, p)) for p in pts])
    mesh.CreateFaceVertexCountsAttr([len(f) for f in faces])
    mesh.CreateFaceVertexIndicesAttr([int(i) for f in faces for i in f])
    mesh.CreateSubdivisionSchemeAttr("none")
    if scattering is not None:
        set_material(mesh.GetPrim(), scattering, **material)
    return mesh


def add_disk_light(stage: Usd.Stage, path: str, radius: float, flux: float = 1000.0,
                   unit: float = 1.0, translate=(0.0, 0.0, 0.0), rotate_x: float = 0.0,
                   cone_angle: float | None = None) -> UsdLux.DiskLight:
    """A one-sided DiskLight (emitting along its local -Z) of ``radius`` (m)."""
    light = UsdLux.DiskLight.Define(stage, path)
    light.CreateRadiusAttr(radius / unit)
    _place(light, translate, unit, rotate_x)
    _flux(light, flux, cone_angle)
    return light


def add_sphere_light(stage: Usd.Stage, path: str, radius: float, flux: float = 1000.0,
                     unit: float = 1.0, translate=(0.0, 0.0, 0.0),
                     point: bool = False) -> UsdLux.SphereLight:
    light = UsdLux.SphereLight.Define(stage, path)
    light.CreateRadiusAttr(radius / unit)
    if point:
        light.CreateTreatAsPointAttr(True)
    _place(light, translate, unit)
    _flux(light, flux, None)
    return light


def _place(light, translate, unit: float, rotate_x: float = 0.0) -> None:
    if any(translate):
        light.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(
            Gf.Vec3d(*(float(t) / unit for t in translate)))
    if rotate_x:
        light.AddRotateXOp(UsdGeom.XformOp.PrecisionDouble).Set(rotate_x)


def _flux(light, flux: float, cone_angle: float | None) -> None:
    prim = light.GetPrim()
    prim.ApplyAPI("LumitraceEmitterAPI")
    prim.GetAttribute("lumitrace:luminousFlux").Set(float(flux))
    if cone_angle is not None:
        shaping = UsdLux.ShapingAPI.Apply(prim)
        shaping.CreateShapingConeAngleAttr(float(cone_angle))


def save_and_read(stage: Usd.Stage) -> Scene:
    stage.GetRootLayer().Save()
    return read_stage(stage.GetRootLayer().realPath)


# -- shapes (metres; faces counter-clockwise seen from outside unless said otherwise) -----

def box(lo, hi, inward: bool = False) -> tuple[np.ndarray, list[list[int]]]:
    """An axis-aligned closed box as 6 quads, normals outward (or inward)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    pts = np.array([[x, y, z] for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)])
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2],
             [1, 3, 7, 5]]
    if inward:
        quads = [q[::-1] for q in quads]
    return pts, quads


def square(half: float, z: float = 0.0, up: bool = True) -> tuple[np.ndarray, list[list[int]]]:
    """A square in the plane z, facing +Z (or -Z)."""
    h = half
    pts = np.array([[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z]], dtype=np.float64)
    return pts, [[0, 1, 2, 3] if up else [3, 2, 1, 0]]


def uv_sphere(radius: float, n_lon: int = 48, n_lat: int = 24, inward: bool = False,
              keep_band: Callable[[int], bool] | None = None):
    """A faceted sphere (vertex rings at polar angles pi i / n_lat), triangles outward (or
    inward); ``keep_band(i)`` drops latitude bands (0 at +Z) to cut openings."""
    theta = np.pi * np.arange(1, n_lat) / n_lat
    phi = 2 * np.pi * np.arange(n_lon) / n_lon
    rings = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                      np.outer(np.cos(theta), np.ones(n_lon))], axis=-1).reshape(-1, 3)
    pts = np.concatenate([rings, [[0, 0, 1], [0, 0, -1]]]) * radius
    north, south = len(rings), len(rings) + 1
    faces, band = [], []
    for j in range(n_lon):
        faces.append([north, j, (j + 1) % n_lon])
        band.append(0)
    for i in range(n_lat - 2):
        for j in range(n_lon):
            a, b = i * n_lon + j, i * n_lon + (j + 1) % n_lon
            faces += [[a, a + n_lon, b + n_lon], [a, b + n_lon, b]]
            band += [i + 1, i + 1]
    last = (n_lat - 2) * n_lon
    for j in range(n_lon):
        faces.append([south, last + (j + 1) % n_lon, last + j])
        band.append(n_lat - 1)
    faces = np.array(faces)
    # make every triangle face outward (its normal along its centroid)
    p = pts[faces]
    out = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p.mean(axis=1)) > 0
    faces[~out] = faces[~out][:, ::-1]
    if inward:
        faces = faces[:, ::-1]
    if keep_band is not None:
        faces = faces[[keep_band(b) for b in band]]
    return pts, faces.tolist()


def cone_frustum(r0: float, z0: float, r1: float, z1: float, n: int = 48):
    """The open side of a cone frustum (no caps), normals away from the axis."""
    phi = 2 * np.pi * np.arange(n) / n
    ring0 = np.stack([r0 * np.cos(phi), r0 * np.sin(phi), np.full(n, z0)], axis=1)
    ring1 = np.stack([r1 * np.cos(phi), r1 * np.sin(phi), np.full(n, z1)], axis=1)
    pts = np.concatenate([ring0, ring1])
    faces = [[j, (j + 1) % n, n + (j + 1) % n, n + j] for j in range(n)]
    return pts, faces


def cylinder(radius: float, z0: float, z1: float, n: int = 48):
    """A closed cylinder (side and caps), normals outward."""
    phi = 2 * np.pi * np.arange(n) / n
    ring0 = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.full(n, z0)], axis=1)
    ring1 = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.full(n, z1)], axis=1)
    pts = np.concatenate([ring0, ring1])
    faces = [[j, (j + 1) % n, n + (j + 1) % n, n + j] for j in range(n)]
    faces += [list(range(n, 2 * n)), list(range(n - 1, -1, -1))]
    return pts, faces


#: The parts of :func:`four_part_luminaire`.
FOUR_PARTS = ("/Luminaire/Reflector", "/Luminaire/Lens", "/Luminaire/Board",
              "/Luminaire/Baffle")


def four_part_luminaire(path: Path) -> Usd.Stage:
    """A disk LED in a glossy cone reflector over a dielectric lens, a diffuse board above
    and a small diffuse baffle below the lens (:data:`FOUR_PARTS`), saved at ``path``."""
    stage = new_stage(path)
    add_disk_light(stage, "/Luminaire/Led", 0.005)
    p, f = cone_frustum(0.01, 0.0, 0.03, -0.04)
    add_mesh(stage, FOUR_PARTS[0], p, f, 1.0, "glossy", specularReflectance=0.9,
             roughness=0.2)
    p, f = cylinder(0.03, -0.046, -0.042)
    add_mesh(stage, FOUR_PARTS[1], p, f, 1.0, "dielectric", ior=1.5, transmittance=1.0)
    p, f = square(0.05, 0.001, up=False)
    add_mesh(stage, FOUR_PARTS[2], p, f, 1.0, "diffuse", reflectance=0.5)
    p, f = cylinder(0.006, -0.06, -0.05)
    add_mesh(stage, FOUR_PARTS[3], p, f, 1.0, "diffuse", reflectance=0.7)
    stage.GetRootLayer().Save()
    return stage


def aim(prim_schema, direction, translate=(0.0, 0.0, 0.0), unit: float = 1.0) -> None:
    """Place a light at ``translate`` (m) with its emission axis (local -Z) along
    ``direction``, as one double-precision transform op (built here: Gf.Rotation takes
    directions less than about 1e-3 rad apart for parallel)."""
    to = np.asarray(direction, dtype=np.float64)
    to = to / np.linalg.norm(to)
    frm = np.array([0.0, 0.0, -1.0])
    axis = np.cross(frm, to)
    s, c = np.linalg.norm(axis), float(np.dot(frm, to))
    if s < 1e-300:
        rot = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        k = axis / s
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        rot = np.eye(3) + s * kx + (1.0 - c) * (kx @ kx)   # column convention: rot @ frm = to
    m = np.eye(4)
    m[:3, :3] = rot.T                                       # USD rows: v_row @ M
    m[3, :3] = np.asarray(translate, dtype=np.float64) / unit
    prim_schema.AddTransformOp(UsdGeom.XformOp.PrecisionDouble).Set(
        Gf.Matrix4d(*map(float, m.ravel())))


def spot(stage: Usd.Stage, path: str, direction, at, cone_angle: float = 1e-5,
         flux: float = 1000.0) -> UsdLux.SphereLight:
    """A point light shaped to a cone of ``cone_angle`` degrees: a pencil of rays from
    ``at`` (m) along ``direction``."""
    light = UsdLux.SphereLight.Define(stage, path)
    light.CreateRadiusAttr(0.0)
    light.CreateTreatAsPointAttr(True)
    aim(light, direction, at)
    _flux(light, flux, cone_angle)
    return light


def mini_downlight(path: Path, unit: float = 1.0, scale: float = 1.0, offset=None) -> Scene:
    """A small downlight with every kind of bounce: a 5 mm LED disc on a board, an open
    faceted reflector cone, a closed glass lens; dimensions in metres, written in ``unit``
    (metersPerUnit), optionally scaled and moved by double-precision ops on the root."""
    stage = new_stage(path, unit, scale=scale, offset=offset)
    add_disk_light(stage, "/Luminaire/Led", 0.005, unit=unit)
    p, f = cone_frustum(0.01, 0.0, 0.03, -0.04)
    add_mesh(stage, "/Luminaire/Reflector", p, f, unit, "diffuse", reflectance=0.85)
    p, f = cylinder(0.03, -0.046, -0.042)
    add_mesh(stage, "/Luminaire/Lens", p, f, unit, "dielectric", ior=1.5, transmittance=1.0)
    p, f = square(0.05, 0.001, up=False)
    add_mesh(stage, "/Luminaire/Board", p, f, unit, "diffuse", reflectance=0.5)
    return save_and_read(stage)


def _moved(a: Traced, b: Traced) -> int:
    """Photons binned differently by two traces of the same photons (each counted once)."""
    return int(np.abs(a.counts - b.counts).sum()) // 2 + abs(a.escaped - b.escaped)


def _result(name, ok, measured, expected, traced: Sequence[Traced] = (), t0=None, **details):
    photons = sum(t.photons for t in traced)
    return CaseResult(name, bool(ok), measured, expected, photons,
                      time.perf_counter() - t0 if t0 is not None else 0.0, details)


def _sound(*traced: Traced) -> bool:
    return all(t.balanced and t.finite for t in traced)


# ------------------------------------------------------------------------------------------
# 1. Scale and unit invariance
# ------------------------------------------------------------------------------------------

#: Photons allowed to take another path through float rounding, per photon traced.
MOVED_PER_PHOTON = 1e-4


def _same_map_case(folder: Path, photons: int, label: str, stem: str,
                   variants: list[tuple[str, dict]], what: str) -> CaseResult:
    """Trace the mini downlight as modelled and in each variant (keyword arguments of
    :func:`mini_downlight`): every variant must give the same map, balanced and finite."""
    t0 = time.perf_counter()
    ref = trace(mini_downlight(folder / f"{stem}_ref.usda"), photons)
    moved, runs = {}, [ref]
    for i, (name, kw) in enumerate(variants):
        r = trace(mini_downlight(folder / f"{stem}_{i}.usda", **kw), photons)
        moved[name] = _moved(ref, r)
        runs.append(r)
    worst = max(moved.values())
    return _result(label, _sound(*runs) and worst <= MOVED_PER_PHOTON * photons,
                   f"photons on another path vs {what}: "
                   + ", ".join(f"{k} {v}" for k, v in moved.items()),
                   f"<= {MOVED_PER_PHOTON:g} per photon, balanced, finite", runs, t0, moved=moved)


def case_units(folder: Path, photons: int) -> CaseResult:
    """The same downlight modelled in m, mm, cm and inches gives the same map."""
    return _same_map_case(folder, photons, "units m/mm/cm/in", "units",
                          [(u, {"unit": UNITS[u]}) for u in ("mm", "cm", "in")], "m")


def case_scales(folder: Path, photons: int) -> CaseResult:
    """The same downlight scaled by 1e-3 and 1e3 (a double scale op) gives the same map."""
    return _same_map_case(folder, photons, "scale 1e-3/1/1e3", "scale",
                          [(f"x{s:g}", {"scale": s}) for s in (1e-3, 1e3)], "x1")


def case_far_offset(folder: Path, photons: int) -> CaseResult:
    """The downlight 1 km and 10 km from the origin (double translate op) gives the same
    map; in mm, the 1 km offset is 1e6 units."""
    return _same_map_case(folder, photons, "far from the origin", "offset", [
        ("1 km", {"offset": (1000.0, 1000.0, 1000.0)}),
        ("10 km", {"offset": (1e4, -1e4, 1e4)}),
        ("1 km in mm", {"unit": 0.001, "offset": (1e6, 1e6, 1e6)})], "the origin")


def case_die_in_2m_luminaire(folder: Path, photons: int) -> CaseResult:
    """A 1 mm LED die 0.5 mm above a 2 m x 2 m x 4 mm clear glass slab (n = 1.5): the slab
    transmits the closed-form fraction of a Lambertian source, in mm and in m alike."""
    from lumitrace.report.references import lambertian_slab_flux

    t0 = time.perf_counter()
    expected, _ = lambertian_slab_flux(1.5)
    runs, fractions = [], []
    for name, unit in (("m", 1.0), ("mm", 0.001)):
        stage = new_stage(folder / f"die_{name}.usda", unit)
        add_disk_light(stage, "/Luminaire/Die", 0.0005, unit=unit, translate=(0, 0, 0.0005))
        p, f = box((-1, -1, -0.004), (1, 1, 0.0))
        add_mesh(stage, "/Luminaire/Slab", p, f, unit, "dielectric", ior=1.5, transmittance=1.0)
        r = trace(save_and_read(stage), photons)
        d = texel_directions(r.resolution)
        runs.append(r)
        fractions.append(r.counts[d[..., 2] < 0].sum() / photons)
    sigma = binomial_sigma(expected, photons)
    z = [(f - expected) / sigma for f in fractions]
    ok = _sound(*runs) and all(abs(v) < 4.5 for v in z) and all(r.absorbed == r.cut == 0 for r in runs)
    return _result("1 mm die over a 2 m slab", ok,
                   f"transmitted {fractions[0]:.5f} (m), {fractions[1]:.5f} (mm); "
                   f"z = {z[0]:+.2f}, {z[1]:+.2f}; moved m/mm {_moved(*runs)}",
                   f"{expected:.5f} (closed form) within 4.5 sigma", runs, t0)


# ------------------------------------------------------------------------------------------
# 2. Geometry that breaks naive tracers
# ------------------------------------------------------------------------------------------

def _closed(name: str, build, photons: int, folder: Path, max_depth: int = MAX_DEPTH,
            expect_cut_all: bool = False, t0=None, note: str = "") -> CaseResult:
    stage = new_stage(folder / f"{name.replace(' ', '_')}.usda")
    build(stage)
    scene = save_and_read(stage)
    r = trace(scene, photons, max_depth=max_depth)
    ok = _sound(r) and r.escaped == 0 and (r.cut == photons if expect_cut_all else True)
    return _result(name, ok, r.fractions() + (f"; {note}" if note else ""),
                   "escaped exactly 0 (nothing leaks)" +
                   ("; every photon cut at the depth limit" if expect_cut_all else ""),
                   [r], t0, warnings=scene.warnings)


BOX_LO, BOX_HI = (-0.3, -0.2, -0.25), (0.35, 0.3, 0.2)


def case_edge_aimed(folder: Path, photons: int) -> CaseResult:
    """Pencils of rays aimed exactly at a concave edge and at a corner of a closed box of
    reflectance 1 (diffuse and mirror): nothing leaks out at the edges."""
    t0 = time.perf_counter()
    runs, leaked = [], {}
    for scattering in ("diffuse", "mirror"):
        for target in ((1, 1, 0), (1, 1, 1), (0.3, 1, 1)):
            stage = new_stage(folder / f"edge_{scattering}_{len(runs)}.usda")
            spot(stage, "/Luminaire/Spot", target, (0, 0, 0))
            p, f = box((-1, -1, -1), (1, 1, 1), inward=True)
            add_mesh(stage, "/Luminaire/Box", p, f, 1.0, scattering, reflectance=1.0,
                     specularReflectance=1.0)
            r = trace(save_and_read(stage), photons // 6, max_depth=8)
            runs.append(r)
            leaked[f"{scattering} {target}"] = r.escaped
    ok = _sound(*runs) and not any(leaked.values())
    return _result("rays aimed at box edges", ok,
                   f"escaped {sum(leaked.values())} of {sum(r.photons for r in runs):,} "
                   "(before the fix: 4-12% at every edge and corner)",
                   "0 escaped", runs, t0, leaked=leaked)


def case_white_closed_box(folder: Path, photons: int, max_depth: int = 64) -> CaseResult:
    """A source inside a closed diffuse box of reflectance 1: every photon bounces until the
    depth limit; none escapes, none is absorbed."""
    def build(stage):
        add_sphere_light(stage, "/Luminaire/Bulb", 0.01, translate=(0.1, 0.05, 0.02))
        p, f = box(BOX_LO, BOX_HI, inward=True)
        add_mesh(stage, "/Luminaire/Box", p, f, 1.0, "diffuse", reflectance=1.0)
    return _closed("closed white box", build, photons, folder, max_depth, expect_cut_all=True,
                   t0=time.perf_counter())


def case_coincident_faces(folder: Path, photons: int) -> CaseResult:
    """A closed box whose every wall is there twice, coincident, with two materials."""
    def build(stage):
        add_sphere_light(stage, "/Luminaire/Bulb", 0.01, translate=(0.1, 0.05, 0.02))
        p, f = box(BOX_LO, BOX_HI, inward=True)
        add_mesh(stage, "/Luminaire/White", p, f, 1.0, "diffuse", reflectance=0.95)
        add_mesh(stage, "/Luminaire/Mirror", p, f, 1.0, "mirror", specularReflectance=0.95)
    return _closed("coincident faces", build, photons, folder, t0=time.perf_counter())


def case_overlapping_faces(folder: Path, photons: int) -> CaseResult:
    """A closed box whose walls are each two overlapping quads."""
    def build(stage):
        add_sphere_light(stage, "/Luminaire/Bulb", 0.01)
        p, f = box(BOX_LO, BOX_HI, inward=True)
        pts, faces = [], []
        for q in f:
            a, b, c, d = p[q]
            for s0, s1 in ((0.0, 0.6), (0.4, 1.0)):
                n = len(pts)
                pts += [a + s0 * (b - a), a + s1 * (b - a), d + s1 * (c - d), d + s0 * (c - d)]
                faces.append([n, n + 1, n + 2, n + 3])
        add_mesh(stage, "/Luminaire/Box", np.array(pts), faces, 1.0, "diffuse", reflectance=0.95)
    return _closed("overlapping faces", build, photons, folder, t0=time.perf_counter())


def case_sliver_triangles(folder: Path, photons: int) -> CaseResult:
    """A closed box whose walls are fans of sliver triangles (widths down to 1e-7 of their
    length) plus zero-area triangles (a repeated corner, collinear corners)."""
    def build(stage):
        add_sphere_light(stage, "/Luminaire/Bulb", 0.01)
        p, f = box(BOX_LO, BOX_HI, inward=True)
        pts, faces = [], []
        for q in f:
            a, b, c, d = p[q]
            edge = [a + (b - a) * s for s in np.concatenate([[0.0], np.geomspace(1e-7, 1.0, 40)])]
            n = len(pts)
            pts += edge + [d, c]
            ie, i_d, i_c = list(range(n, n + len(edge))), n + len(edge), n + len(edge) + 1
            faces += [[ie[i], ie[i + 1], i_d] for i in range(len(edge) - 1)]
            faces += [[ie[-1], i_c, i_d], [ie[0], ie[0], ie[1]], [ie[0], ie[1], ie[2]]]
        add_mesh(stage, "/Luminaire/Box", np.array(pts), faces, 1.0, "diffuse", reflectance=0.95)
    res = _closed("sliver and zero-area triangles", build, photons, folder, t0=time.perf_counter())
    dropped = [w for w in res.details["warnings"] if "zero-area" in w]
    res.ok = res.ok and bool(dropped)
    res.measured += f"; {dropped[0].split(': ', 1)[1] if dropped else 'no warning'}"
    return res


def case_open_bowl(folder: Path, photons: int) -> CaseResult:
    """An open hemispherical absorber (faceted) over a point source at its centre: exactly
    half the flux escapes, all of it below the rim."""
    t0 = time.perf_counter()
    stage = new_stage(folder / "bowl.usda")
    add_sphere_light(stage, "/Luminaire/Point", 0.0, point=True)
    p, f = uv_sphere(0.1, 48, 24, inward=True, keep_band=lambda b: b < 12)
    add_mesh(stage, "/Luminaire/Bowl", p, f, 1.0, "absorber")
    r = trace(save_and_read(stage), photons)
    up = int(r.counts[texel_directions(r.resolution)[..., 2] > 0].sum())
    z = (r.escaped / photons - 0.5) / binomial_sigma(0.5, photons)
    return _result("open mesh (absorbing bowl)", _sound(r) and abs(z) < 4.5 and up == 0,
                   f"escaped {r.escaped / photons:.5f} (z = {z:+.2f}), above the rim {up}",
                   "0.5 within 4.5 sigma, 0 above the rim", [r], t0)


def case_sheet_both_sides(folder: Path, photons: int) -> CaseResult:
    """A zero-thickness sheet lit from above and from below: opaque diffuse (r = 0.6) sends
    nothing through; translucent (r = 0.3, t = 0.5) reflects, transmits and absorbs the
    closed-form fractions, the same from either side."""
    t0 = time.perf_counter()
    runs, parts, ok = [], [], True
    for scattering, r_, t_ in (("diffuse", 0.6, 0.0), ("translucent", 0.3, 0.5)):
        stage = new_stage(folder / f"sheet_{scattering}.usda")
        add_disk_light(stage, "/Luminaire/Above", 0.001, translate=(0.1, 0.0, 0.001))
        add_disk_light(stage, "/Luminaire/Below", 0.001, translate=(-0.1, 0.0, -0.001),
                       rotate_x=180.0)
        p, f = square(1.0, 0.0)
        add_mesh(stage, "/Luminaire/Sheet", p, f, 1.0, scattering, reflectance=r_,
                 transmittance=t_)
        scene = save_and_read(stage)
        for e, side in zip(scene.emitters, (-1.0, 1.0)):   # side the light faces (z sign)
            one = dataclasses.replace(scene, emitters=(e,))
            r = trace(one, photons // 4)
            runs.append(r)
            dz = texel_directions(r.resolution)[..., 2]
            through = r.counts[dz * side > 0.02].sum() / r.photons
            back = r.counts[dz * side < -0.02].sum() / r.photons
            n = r.photons
            z_t = (through - t_) / max(binomial_sigma(t_, n), 1.0 / n)
            z_r = (back - r_) / binomial_sigma(r_, n)
            ok &= abs(z_t) < 4.5 and abs(z_r) < 4.5 and (t_ > 0 or through == 0)
            parts.append(f"{scattering} from {'above' if side < 0 else 'below'}: "
                         f"back {back:.4f} through {through:.4f}")
    ok &= _sound(*runs)
    return _result("zero-thickness sheet, both sides", ok, "; ".join(parts),
                   "opaque: back 0.6, through 0; translucent: back 0.3, through 0.5 (4.5 sigma)",
                   runs, t0)


def case_flipped_normals(folder: Path, photons: int) -> CaseResult:
    """Flipped windings: on two-sided parts (diffuse reflector, board) the map is
    unchanged; a glass slab with every face flipped is detected by its negative volume,
    flipped back with a warning, and transmits the closed-form fraction."""
    from lumitrace.report.references import lambertian_slab_flux

    t0 = time.perf_counter()
    ref = trace(mini_downlight(folder / "normals_ref.usda"), photons)
    stage = Usd.Stage.Open(str(folder / "normals_ref.usda"))
    stage.GetRootLayer().Export(str(folder / "normals_flipped.usda"))
    flipped = Usd.Stage.Open(str(folder / "normals_flipped.usda"))
    for name in ("Reflector", "Board", "Lens"):
        UsdGeom.Mesh(flipped.GetPrimAtPath(f"/Luminaire/{name}")).CreateOrientationAttr(
            UsdGeom.Tokens.leftHanded)
    flipped.GetRootLayer().Save()
    scene = read_stage(folder / "normals_flipped.usda")
    r = trace(scene, photons)
    moved = _moved(ref, r)
    warned = any("Lens" in w and "faces inward" in w for w in scene.warnings)
    slabs = []
    for inward in (False, True):
        st = new_stage(folder / f"slab_{inward}.usda")
        add_disk_light(st, "/Luminaire/Source", 0.05)
        p, f = box((-20, -20, -0.02), (20, 20, -0.01), inward=inward)
        add_mesh(st, "/Luminaire/Slab", p, f, 1.0, "dielectric", ior=1.5, transmittance=1.0)
        slabs.append(trace(save_and_read(st), photons))
    expected, _ = lambertian_slab_flux(1.5)
    d = texel_directions(ref.resolution)
    down = slabs[1].counts[d[..., 2] < 0].sum() / photons
    z = (down - expected) / binomial_sigma(expected, photons)
    slab_moved = _moved(*slabs)
    ok = (_sound(ref, r, *slabs) and warned and moved <= MOVED_PER_PHOTON * photons
          and slab_moved <= MOVED_PER_PHOTON * photons and abs(z) < 4.5)
    return _result("flipped normals", ok,
                   f"downlight with every winding flipped: {moved} photons on another path, "
                   f"lens flipped back: {warned}; flipped slab transmits {down:.4f} (z = {z:+.2f}), "
                   f"{slab_moved} photons on another path than the right one "
                   "(unfixed: 0.381)",
                   f"same map; slab {expected:.4f}", [ref, r, *slabs], t0)


def case_grazing_mirror(folder: Path, photons: int) -> CaseResult:
    """Pencils of rays grazing a mirror plane at 1e-2, 1e-4 and 1e-6 rad: every photon is
    reflected (none crosses the plane), and leaves."""
    t0 = time.perf_counter()
    runs, crossed = [], {}
    for a in (1e-2, 1e-4, 1e-6):
        stage = new_stage(folder / f"graze_{a:g}.usda")
        spot(stage, "/Luminaire/Spot", (-math.sin(a), 0.0, -math.cos(a)), (math.tan(a), 0.0, 0.37))
        p = np.array([[0, -1, -1.63], [0, 1, -1.63], [0, 1, 0.37], [0, -1, 0.37]])
        add_mesh(stage, "/Luminaire/Mirror", p, [[0, 1, 2, 3]], 1.0, "mirror",
                 specularReflectance=1.0)
        r = trace(save_and_read(stage), photons // 3)
        runs.append(r)
        d = texel_directions(r.resolution)
        crossed[f"{a:g}"] = int(r.counts[d[..., 0] < 0].sum())
    ok = _sound(*runs) and not any(crossed.values()) and all(r.escaped == r.photons for r in runs)
    return _result("rays grazing a mirror", ok,
                   "photons on the far side: " + ", ".join(f"{k} rad {v}" for k, v in crossed.items()),
                   "0; all escape", runs, t0)


def case_source_touching_reflector(folder: Path, photons: int) -> CaseResult:
    """An LED disc lying on a white board (coincident planes), emitting away from it: no
    photon gets through the board, and the map is the bare disc's."""
    t0 = time.perf_counter()
    runs = []
    for board in (False, True):
        stage = new_stage(folder / f"touch_{board}.usda")
        add_disk_light(stage, "/Luminaire/Led", 0.002, translate=(0.3, 0.2, 0.37))
        if board:
            p, f = square(1.0, 0.37)
            add_mesh(stage, "/Luminaire/Board", p, f, 1.0, "diffuse", reflectance=1.0)
        p, f = box((-1, -1, -0.8), (1, 1, -0.7))
        add_mesh(stage, "/Luminaire/Far", p, f, 1.0, "absorber")
        runs.append(trace(save_and_read(stage), photons))
    d = texel_directions(runs[1].resolution)
    up = int(runs[1].counts[d[..., 2] > 0].sum())
    moved = _moved(*runs)
    return _result("source touching a reflector", _sound(*runs) and up == 0 and moved == 0,
                   f"through the board {up}, photons on another path than without it {moved} "
                   "(before the fix: 2.4e-5 of photons went through)",
                   "0 and 0", runs, t0)


def case_facing_mirrors(folder: Path, photons: int, n: int = 100) -> CaseResult:
    """A pencil between two parallel mirrors 1 cm apart and 1.2 m long, tilted so that it
    makes exactly n reflections before it walks off them, then leaves in the direction the
    reflections predict; and one perpendicular to them, which never leaves: cut at the depth
    limit, in bounded time."""
    from lumitrace.film.cubemap import texel_index

    t0 = time.perf_counter()
    gap, half = 0.01, 0.6
    direction = np.array([half / (gap * n), 0.05, -1.0])   # x advances 2 half / n a bounce
    direction /= np.linalg.norm(direction)
    stage = new_stage(folder / "facing.usda")
    spot(stage, "/Luminaire/Spot", direction, (0, 0, 0))
    stage2 = new_stage(folder / "endless.usda")
    spot(stage2, "/Luminaire/Spot", (0.0, 0.0, -1.0), (0, 0, 0))
    for st in (stage, stage2):
        for z, name in ((-gap / 2, "Low"), (gap / 2, "High")):
            p, f = square(1.0, z)
            p[:, 0] *= half
            p[:, 1] *= 0.2
            add_mesh(st, f"/Luminaire/{name}", p, f, 1.0, "mirror", specularReflectance=1.0)
    scene, endless = save_and_read(stage), save_and_read(stage2)
    short = trace(scene, photons // 4, max_depth=n - 1)
    enough = trace(scene, photons // 4, max_depth=n)
    final = direction * np.array([1.0, 1.0, (-1.0) ** n])
    texel = int(texel_index(final[None, :], enough.resolution)[0])
    in_texel = int(enough.counts.ravel()[texel])
    t1 = time.perf_counter()
    forever = trace(endless, photons // 4)
    seconds = time.perf_counter() - t1
    ok = (_sound(short, enough, forever) and short.cut == short.photons
          and enough.escaped == in_texel == enough.photons and forever.cut == forever.photons)
    return _result("mirrors facing each other", ok,
                   f"depth {n - 1}: cut {short.cut / short.photons:.3f}; depth {n}: escaped "
                   f"{enough.escaped / enough.photons:.3f}, in the predicted texel "
                   f"{in_texel / enough.photons:.3f}; perpendicular: cut "
                   f"{forever.cut / forever.photons:.3f} after {MAX_DEPTH} bounces in {seconds:.1f} s",
                   f"exactly {n} reflections, all in one texel; endless ones cut",
                   [short, enough, forever], t0)


def case_tir_cube(folder: Path, photons: int) -> CaseResult:
    """A point source inside a glass cube (n = 1.5): directions with every |d_i| below
    cos(critical angle) = sqrt(1 - 1/n^2) are totally reflected at every face forever, a
    fraction 3 sqrt(1 - 1/n^2) - 2 (the six escape cones do not overlap); they are cut at
    the depth limit, all others escape; nothing is absorbed."""
    t0 = time.perf_counter()
    stage = new_stage(folder / "tir.usda")
    add_sphere_light(stage, "/Luminaire/Point", 0.0, point=True, translate=(0.01, -0.02, 0.03))
    p, f = box((-0.1, -0.1, -0.1), (0.1, 0.1, 0.1))
    add_mesh(stage, "/Luminaire/Cube", p, f, 1.0, "dielectric", ior=1.5, transmittance=1.0)
    r = trace(save_and_read(stage), photons, max_depth=256)
    trapped = 3.0 * math.sqrt(1.0 - 1.0 / 1.5 ** 2) - 2.0
    z = (r.cut / photons - trapped) / binomial_sigma(trapped, photons)
    return _result("total internal reflection", _sound(r) and abs(z) < 4.5 and r.absorbed == 0,
                   f"cut {r.cut / photons:.5f} (z = {z:+.2f}), escaped {r.escaped / photons:.5f}",
                   f"trapped {trapped:.5f} within 4.5 sigma", [r], t0)


# ------------------------------------------------------------------------------------------
# 5. White furnace and energy
# ------------------------------------------------------------------------------------------

def _integrating_sphere(folder: Path, name: str, reflectance: float, scattering: str = "diffuse"):
    """A faceted sphere (radius 0.1 m) with a port of 22.5 degrees around -Z and a disc
    source at the +Z pole facing the wall: (scene, port area fraction)."""
    n_lat, port = 48, 6
    stage = new_stage(folder / f"{name}.usda")
    pts, faces = uv_sphere(0.1, 96, n_lat, inward=True)
    faces = np.asarray(faces)
    keep = _bands(pts, faces, n_lat) < n_lat - port
    q = pts[faces]
    area = np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1)
    fraction = area[~keep].sum() / area.sum()
    p, f = pts, faces[keep].tolist()
    add_mesh(stage, "/Luminaire/Sphere", p, f, 1.0, scattering, reflectance=reflectance,
             specularReflectance=reflectance)
    add_disk_light(stage, "/Luminaire/Source", 0.005, translate=(0, 0, 0.094), rotate_x=180.0)
    return save_and_read(stage), float(fraction)


def _bands(points, faces, n_lat: int) -> np.ndarray:
    """Latitude band (0 at +Z) of each triangle of :func:`uv_sphere`."""
    c = np.asarray(points)[np.asarray(faces)].mean(axis=1)
    theta = np.arccos(np.clip(c[:, 2] / np.linalg.norm(c, axis=1), -1, 1))
    return np.floor(theta / (np.pi / n_lat)).astype(int)


def case_white_furnace(folder: Path, photons: int) -> CaseResult:
    """Enclosures of reflectance 1 with an opening let all the flux out: a diffuse sphere
    with a port, exactly (as integers); a mirror box with a square hole, all but the
    photons on closed orbits longer than the depth limit."""
    t0 = time.perf_counter()
    scene, f = _integrating_sphere(folder, "furnace", 1.0)
    r = trace(scene, photons)
    stage = new_stage(folder / "mirror_furnace.usda")
    add_sphere_light(stage, "/Luminaire/Bulb", 0.01, translate=(0.05, 0.02, 0.0))
    p, q = box((-0.2, -0.2, -0.2), (0.2, 0.2, 0.2), inward=True)
    q = q[1:]                                        # no floor: the opening ...
    p2, q2 = square(0.2, -0.2, up=True)              # ... half closed by a ring
    hole = np.array([[-0.05, -0.05, -0.2], [0.05, -0.05, -0.2], [0.05, 0.05, -0.2], [-0.05, 0.05, -0.2]])
    pts = np.concatenate([p, p2, hole])
    o, h = len(p), len(p) + 4
    ring = [[o, o + 1, h + 1, h], [o + 1, o + 2, h + 2, h + 1], [o + 2, o + 3, h + 3, h + 2],
            [o + 3, o, h, h + 3]]
    add_mesh(stage, "/Luminaire/Box", pts, q + ring, 1.0, "mirror", specularReflectance=1.0)
    mirror = save_and_read(stage)
    m_short = trace(mirror, photons // 2, max_depth=MAX_DEPTH // 4)
    m = trace(mirror, photons // 2)
    ok = (_sound(r, m, m_short) and r.escaped == r.photons and r.absorbed == r.cut == 0
          and m.absorbed == m_short.absorbed == 0 and m.cut < m_short.cut)
    return _result("white furnace (reflectance 1)", ok,
                   f"diffuse sphere (port {f:.4f}): {r.fractions()}, {r.segments / r.photons:.1f} "
                   f"segments/photon; mirror box: cut {m_short.cut / m_short.photons:.4f} at "
                   f"depth {MAX_DEPTH // 4}, {m.cut / m.photons:.4f} at {MAX_DEPTH} (closed "
                   "specular orbits), absorbed 0",
                   "sphere: escaped == photons exactly; mirror box: nothing absorbed, what is "
                   "not out is cut and falls with depth", [r, m_short, m], t0)


def case_furnace_reflectance(folder: Path, photons: int, reflectances=(0.5, 0.9)) -> CaseResult:
    """A diffuse sphere of reflectance r < 1 with a port of area fraction f lets out
    r f / (1 - r (1 - f)) of the flux of a source facing its wall; a single diffuse plane
    reflects exactly r."""
    t0 = time.perf_counter()
    runs, parts, ok = [], [], True
    for rho in reflectances:
        scene, f = _integrating_sphere(folder, f"sphere_{rho:g}", rho)
        r = trace(scene, photons // len(reflectances))
        want = rho * f / (1.0 - rho * (1.0 - f))
        got = r.escaped / r.photons
        z = (got - want) / binomial_sigma(want, r.photons)
        ok &= abs(z) < 4.5 and r.cut == 0
        runs.append(r)
        parts.append(f"sphere r={rho:g}: {got:.5f} vs {want:.5f} (z = {z:+.2f})")
    stage = new_stage(folder / "plane.usda")
    add_disk_light(stage, "/Luminaire/Source", 0.001, translate=(0, 0, 0.001))
    p, q = square(1.0, 0.0)
    add_mesh(stage, "/Luminaire/Plane", p, q, 1.0, "diffuse", reflectance=0.37)
    r = trace(save_and_read(stage), photons // 2)
    z = (r.escaped / r.photons - 0.37) / binomial_sigma(0.37, r.photons)
    ok &= abs(z) < 4.5 and _sound(r, *runs)
    parts.append(f"plane r=0.37: {r.escaped / r.photons:.5f} (z = {z:+.2f})")
    return _result("closed-form escape fraction (r < 1)", ok, "; ".join(parts),
                   "r f / (1 - r (1 - f)) and r, within 4.5 sigma", runs + [r], t0)


# ------------------------------------------------------------------------------------------
# 3. Accumulation at scale
# ------------------------------------------------------------------------------------------

def _point_scene(flux: float = 1000.0) -> Scene:
    from lumitrace.scene import Emitter

    e = Emitter(path="/Luminaire/Point", kind="sphere", flux=flux, to_world=np.eye(4),
                radius=0.0, treat_as_point=True)
    return Scene(triangles=np.zeros((0, 3, 3)), material_index=np.zeros(0, np.int32),
                 part_index=np.zeros(0, np.int32), materials=(), parts=(), emitters=(e,))


def case_accumulator_at_scale(folder: Path, photons: int, batches: int = 1000) -> CaseResult:
    """Tallies of 1000 batches of 2^31 + 7 photons each (2.1e12 photons) added to an
    Accumulator: photon counts stay exact integers, and the float64 intensities of texels
    holding 1 photon and 1e12 photons are exact to float64 rounding: 2e-7 to 1e6 cd in one
    map."""
    from fractions import Fraction

    from lumitrace.film.accumulate import Accumulator
    from lumitrace.film.cubemap import texel_solid_angles
    from lumitrace.film.tally import BatchTally

    t0 = time.perf_counter()
    res = 64
    flux = 50.0
    scene = _point_scene(flux)
    acc = Accumulator(scene, res)
    per_batch = 2 ** 31 + 7
    ntex = 6 * res * res
    counts = np.zeros((2, ntex), np.int64)
    counts[0, 0] = per_batch // 2 - 11       # a bright texel, about half of all photons
    counts[1, 0] = per_batch // 2 - 12
    counts[1, 1] = 3                         # a dim texel; photon 1 of 1000 batches ...
    for b in range(batches):
        c = counts.copy()
        c[0, 2] = 1 if b == 0 else 0         # ... and a texel with one photon in all
        rest = per_batch - int(c.sum())
        acc.add(BatchTally(0, b * per_batch, per_batch, c, absorbed=rest - 5, cut=5))
    t = acc.emitters[0]
    total = batches * per_batch
    bright = batches * int(counts[:, 0].sum())
    exact_counts = (t.photons == total and t.escaped + t.absorbed + t.cut == total
                    and int(acc.counts()[0, 0]) == bright and acc.counts().dtype == np.int64)
    omega = texel_solid_angles(res).ravel()
    intensity = acc.intensity().ravel()
    worst = 0.0
    for texel, n in ((0, bright), (1, 3 * batches), (2, 1)):
        want = Fraction(flux) * n / total / Fraction(float(omega[texel]))
        worst = max(worst, abs(float((Fraction(float(intensity[texel])) - want) / want)))
    f = acc.fluxes()
    balance = abs(f["escaped"] + f["absorbed"] + f["cut"] - f["emitted"]) / f["emitted"]
    f32 = np.float32(2 ** 31) + np.float32(7) - np.float32(2 ** 31)   # what float32 would do
    ok = exact_counts and worst < 4e-16 and balance < 1e-15
    return _result("accumulation of 2.1e12 photons", ok,
                   f"counts exact: {exact_counts}; intensities from {intensity[2]:.2e} to "
                   f"{intensity[0]:.2e} cd exact to {worst:.1e}; flux balance {balance:.1e} "
                   f"(a float32 sum would turn 2^31 + 7 - 2^31 into {f32:g})",
                   "exact integer counts; float64 rounding only", (), t0)


def case_exr_dynamic_range(folder: Path, photons: int) -> CaseResult:
    """A map whose texels span 1e-6 to 1e6 cd round-trips through the float32 EXR to
    within float32 rounding of each texel (relative 2^-24)."""
    from lumitrace.publish.exr import read_intensity_exr, write_intensity_exr

    t0 = time.perf_counter()
    res = 32
    rng_ = np.random.default_rng(5)
    image = 10.0 ** rng_.uniform(-6.0, 6.0, size=(6 * res, res))
    image.ravel()[:2] = (1e-6, 1e6)
    counts = np.floor(10.0 ** rng_.uniform(0, 9, size=image.shape))
    path = folder / "range.intensity.exr"
    write_intensity_exr(path, {"Y": image, "raw.Y": image, "count": counts},
                        {"photons": 10 ** 12, "resolution": res})
    channels, meta, _ = read_intensity_exr(path)
    rel = np.abs(channels["Y"].astype(np.float64) - image) / image
    rel_count = np.abs(channels["count"].astype(np.float64) - counts) / counts
    ok = rel.max() <= 2.0 ** -24 and rel_count.max() <= 2.0 ** -24 and meta["photons"] == 10 ** 12
    return _result("EXR round trip, 1e-6 to 1e6 cd", ok,
                   f"largest relative change {rel.max():.2e} (cd), {rel_count.max():.2e} (counts "
                   f"to 1e9); photons in metadata {meta['photons']}",
                   f"<= 2^-24 = {2.0 ** -24:.2e}", (), t0)


def case_photon_index_beyond_2_32(folder: Path, photons: int) -> CaseResult:
    """Photons numbered past 2^32 and 2^40 (a run of 1e12 photons) trace like any others:
    finite, balanced, and not the same photons as those numbered from 0."""
    t0 = time.perf_counter()
    scene = mini_downlight(folder / "index.usda")
    ps = prepare(scene)
    out = {}
    for start in (0, 2 ** 32 - photons // 2, 2 ** 40):
        t = trace_batch(ps, BatchJob(0, start, photons, 1, 8), record_rays=True)
        finite = all(np.isfinite(o).all() and np.isfinite(d).all() for o, d in t.rays)
        out[start] = (t, finite)
    same_low = trace_batch(ps, BatchJob(0, 0, photons, 1, 8))
    distinct = not np.array_equal(out[0][0].counts, out[2 ** 40][0].counts)
    ok = (all(f and t.escaped + t.absorbed + t.cut == t.photons for t, f in out.values())
          and distinct and np.array_equal(same_low.counts, out[0][0].counts))
    esc = ", ".join(f"{t.escaped / t.photons:.4f}" for t, _ in out.values())
    return _result("photon numbers past 2^32", ok,
                   f"escaped fractions from 0, 2^32, 2^40: {esc}; distinct streams {distinct}",
                   "finite, balanced, distinct, reproducible", (), t0)


# ------------------------------------------------------------------------------------------
# 4. Bad input through the command line
# ------------------------------------------------------------------------------------------

def run_cli(args: Sequence[str]) -> tuple[int, str, float]:
    """Run ``lumitrace`` in this process: exit code, everything written to stderr (Python's
    and USD's own C++ output, captured at the file descriptor) and seconds. An exception
    escaping ``main`` is reported as a traceback, as the console script would print it."""
    import contextlib
    import traceback

    from lumitrace.cli import main

    t0 = time.perf_counter()
    py_err = io.StringIO()
    with tempfile.TemporaryFile() as c_err, open(os.devnull, "w") as null:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(c_err.fileno(), 2)
        try:
            with contextlib.redirect_stderr(py_err), contextlib.redirect_stdout(null):
                try:
                    code = main([str(a) for a in args])
                except SystemExit as exc:
                    code = exc.code if isinstance(exc.code, int) else 1
                except BaseException:  # noqa: BLE001 - the point is to see it
                    py_err.write("Traceback (most recent call last):\n" + traceback.format_exc())
                    code = 1
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        c_err.seek(0)
        text = py_err.getvalue() + c_err.read().decode("utf-8", "replace")
    return code, text, time.perf_counter() - t0


def _base_stage(path: Path) -> Usd.Stage:
    """A valid small luminaire: a disc LED, a box part with its own material, a part under
    a transform bound to a UsdShade material with the lumitrace API."""
    from pxr import UsdShade

    stage = new_stage(path)
    add_disk_light(stage, "/Luminaire/Led", 0.01)
    p, f = box((-0.1, -0.1, -0.2), (0.1, 0.1, -0.15))
    add_mesh(stage, "/Luminaire/Box", p, f, 1.0, "diffuse", reflectance=0.8)
    part = UsdGeom.Xform.Define(stage, "/Luminaire/Part")
    part.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(0, 0, -0.3))
    p, f = square(0.2, 0.0)
    mesh = add_mesh(stage, "/Luminaire/Part/Plate", p, f)
    material = UsdShade.Material.Define(stage, "/Luminaire/Looks/Paint")
    set_material(material.GetPrim(), "diffuse", reflectance=0.7)
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    return stage


def _edit(path: Path, edit) -> Path:
    stage = _base_stage(path)
    edit(stage)
    stage.GetRootLayer().Save()
    return path


def _set(prim_path: str, name: str, value):
    def edit(stage):
        stage.GetPrimAtPath(prim_path).GetAttribute(name).Set(value)
    return edit


def _points(value):
    def edit(stage):
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Luminaire/Box"))
        pts = list(mesh.GetPointsAttr().Get())
        pts[3] = Gf.Vec3f(value, 0.0, 0.0)
        mesh.GetPointsAttr().Set(pts)
    return edit


def _op(prim_path: str, kind: str, value):
    def edit(stage):
        xf = UsdGeom.Xformable(stage.GetPrimAtPath(prim_path))
        op = xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble, "bad") if kind == "translate" \
            else xf.AddScaleOp(UsdGeom.XformOp.PrecisionDouble)
        op.Set(Gf.Vec3d(*value))
    return edit


def _arc(kind: str):
    def edit(stage):
        prim = stage.GetPrimAtPath("/Luminaire/Part")
        if kind == "reference":
            prim.GetReferences().AddReference("./missing_part.usda")
        elif kind == "payload":
            prim.GetPayloads().AddPayload("./missing_payload.usda")
        elif kind == "sublayer":
            stage.GetRootLayer().subLayerPaths.append("./missing_sublayer.usda")
        else:  # a cycle: Part references a layer that references Part back
            other = Sdf.Layer.CreateNew(str(Path(stage.GetRootLayer().realPath).with_name("loop.usda")))
            spec = Sdf.CreatePrimInLayer(other, "/Loop")
            spec.specifier = Sdf.SpecifierDef
            spec.referenceList.Prepend(Sdf.Reference(Path(stage.GetRootLayer().realPath).name,
                                                     "/Luminaire/Part"))
            other.defaultPrim = "Loop"
            other.Save()
            prim.GetReferences().AddReference("./loop.usda")
    return edit


def _token(kind: str):
    def edit(stage):
        if kind == "orientation":
            UsdGeom.Mesh(stage.GetPrimAtPath("/Luminaire/Box")).CreateOrientationAttr("sideways")
        else:
            UsdGeom.Cylinder.Define(stage, "/Luminaire/Post").CreateAxisAttr("W")
    return edit


def _write(content: bytes | None = None, size: int = 0, name: str = "bad.usda"):
    """A file of raw ``content``, extended (sparse: no disk used) to ``size`` bytes."""
    def make(folder: Path) -> Path:
        path = folder / name
        with open(path, "wb") as fh:
            if content:
                fh.write(content)
            if size:
                fh.truncate(size)
        return path
    return make


def _no_emitter(folder: Path) -> Path:
    path = folder / "dark.usda"
    stage = _base_stage(path)
    stage.RemovePrim("/Luminaire/Led")
    stage.GetRootLayer().Save()
    return path


def _empty(folder: Path) -> Path:
    path = folder / "empty.usda"
    stage = Usd.Stage.CreateNew(str(path))
    stage.GetRootLayer().Save()
    return path


TWO_GIB = 2 ** 31

#: (name, stage maker (folder -> path), fragments the one error line must contain).
BAD_INPUTS: list[tuple[str, Callable[[Path], Path], tuple[str, ...]]] = [
    ("NaN point", lambda d: _edit(d / "s.usda", _points(float("nan"))),
     ("/Luminaire/Box.points", "NaN")),
    ("Inf point", lambda d: _edit(d / "s.usda", _points(float("inf"))),
     ("/Luminaire/Box.points", "infinite")),
    ("NaN translate", lambda d: _edit(d / "s.usda", _op("/Luminaire/Part", "translate", (float("nan"), 0, 0))),
     ("/Luminaire/Part.xformOp:translate:bad", "NaN")),
    ("Inf scale on a light", lambda d: _edit(d / "s.usda", _op("/Luminaire/Led", "scale", (1, float("inf"), 1))),
     ("/Luminaire/Led.xformOp:scale", "infinite")),
    ("zero scale on a light", lambda d: _edit(d / "s.usda", _op("/Luminaire/Led", "scale", (1, 0, 1))),
     ("/Luminaire/Led.xformOp:scale", "scale of 0")),
    ("negative reflectance", lambda d: _edit(d / "s.usda", _set("/Luminaire/Box", "lumitrace:reflectance", -0.2)),
     ("/Luminaire/Box.lumitrace:reflectance", "[0, 1]")),
    ("reflectance > 1", lambda d: _edit(d / "s.usda", _set("/Luminaire/Looks/Paint", "lumitrace:reflectance", 1.5)),
     ("/Luminaire/Looks/Paint.lumitrace:reflectance", "1.5")),
    ("NaN specular reflectance", lambda d: _edit(d / "s.usda", _set("/Luminaire/Box", "lumitrace:specularReflectance", float("nan"))),
     ("/Luminaire/Box.lumitrace:specularReflectance",)),
    ("ior 0", lambda d: _edit(d / "s.usda", _set("/Luminaire/Box", "lumitrace:ior", 0.0)),
     ("/Luminaire/Box.lumitrace:ior", "> 0")),
    ("ior < 0", lambda d: _edit(d / "s.usda", _set("/Luminaire/Looks/Paint", "lumitrace:ior", -1.5)),
     ("/Luminaire/Looks/Paint.lumitrace:ior", "-1.5")),
    ("unknown scattering token", lambda d: _edit(d / "s.usda", _set("/Luminaire/Box", "lumitrace:scattering", "shiny")),
     ("/Luminaire/Box.lumitrace:scattering", "shiny")),
    ("unknown orientation token", lambda d: _edit(d / "s.usda", _token("orientation")),
     ("/Luminaire/Box.orientation", "sideways")),
    ("unknown axis token", lambda d: _edit(d / "s.usda", _token("axis")),
     ("/Luminaire/Post.axis", "'W'")),
    ("missing referenced layer", lambda d: _edit(d / "s.usda", _arc("reference")),
     ("/Luminaire/Part.references", "missing_part.usda")),
    ("missing payload", lambda d: _edit(d / "s.usda", _arc("payload")),
     ("/Luminaire/Part.payload", "missing_payload.usda")),
    ("missing sublayer", lambda d: _edit(d / "s.usda", _arc("sublayer")),
     ("s.usda.subLayers", "missing_sublayer.usda")),
    ("cyclic reference", lambda d: _edit(d / "s.usda", _arc("cycle")),
     ("/Luminaire/Part.references", "cycle")),
    ("empty stage", _empty, ("empty.usda", "empty")),
    ("no emitter", _no_emitter, ("/Luminaire", "no emitter")),
    ("missing file", lambda d: d / "nowhere.usda", ("nowhere.usda", "not found")),
    ("non-USD text file", _write(b"solid cube\n  facet normal 0 0 1\n", name="part.usda"),
     ("part.usda", "not a USD file")),
    ("PNG named .usd", _write(b"\x89PNG\r\n\x1a\n" + bytes(64), name="image.usd"),
     ("image.usd", "not a USD file")),
    ("2 GiB of zeros (.usda)", _write(None, TWO_GIB, "huge.usda"), ("huge.usda", "not a USD file")),
    ("2 GiB of zeros (.usdc)", _write(None, TWO_GIB, "huge.usdc"), ("huge.usdc", "not a USD file")),
    ("2 GiB after a #usda header", _write(b"#usda 1.0\n", TWO_GIB, "huge_text.usda"),
     ("huge_text.usda", "NUL")),
]


def bad_input_case(name: str, make: Callable[[Path], Path], needles: Sequence[str],
                   folder: Path) -> CaseResult:
    """Run ``lumitrace trace`` on a bad stage: exit 2, exactly one line
    ``lumitrace: error: ...`` naming prim and property (``needles``), no traceback, and
    not a file written next to it."""
    from pxr import UsdUtils

    folder.mkdir(parents=True, exist_ok=True)
    quiet = UsdUtils.CoalescingDiagnosticDelegate()  # USD's warnings while we break the stage
    path = make(folder)
    del quiet
    before = sorted(p.name for p in folder.iterdir())
    code, err, seconds = run_cli(["trace", path, "--photons", "2000", "--resolution", "4",
                                  "--no-progress"])
    after = sorted(p.name for p in folder.iterdir())
    lines = [ln for ln in err.splitlines() if ln.strip()]
    line = lines[0] if lines else ""
    ok = (code == 2 and len(lines) == 1 and line.startswith("lumitrace: error:")
          and all(n in line for n in needles) and "Traceback" not in err and before == after
          and seconds < 10.0)
    shown = line if len(lines) == 1 else f"{len(lines)} lines: {err[:300]!r}"
    return CaseResult(f"bad input: {name}", ok, f"exit {code} in {seconds:.2f} s: {shown}"
                      + ("" if before == after else f"; files written: {set(after) - set(before)}"),
                      "exit 2, one line naming " + " and ".join(repr(n) for n in needles) +
                      ", nothing written", 0, seconds)


def case_results_survive_bad_input(folder: Path, photons: int) -> CaseResult:
    """A stage traced once, then broken: the failing run leaves every file of the first
    run byte for byte as it was."""
    t0 = time.perf_counter()
    path = _base_stage(folder / "kept.usda")
    path.GetRootLayer().Save()
    stage_path = folder / "kept.usda"
    code, err, _ = run_cli(["trace", stage_path, "--photons", "4000", "--resolution", "4",
                            "--no-progress"])
    files = {p.name: p.read_bytes() for p in folder.iterdir()}
    broken = Usd.Stage.Open(str(stage_path))
    _points(float("nan"))(broken)
    broken.GetRootLayer().Save()
    files[stage_path.name] = stage_path.read_bytes()
    code2, err2, _ = run_cli(["trace", stage_path, "--photons", "4000", "--resolution", "4",
                              "--no-progress"])
    after = {p.name: p.read_bytes() for p in folder.iterdir()}
    ok = code == 0 and code2 == 2 and after == files and len(files) > 1
    return _result("results survive bad input", ok,
                   f"first run exit {code}, {len(files) - 1} outputs; failing run exit {code2}; "
                   f"outputs unchanged: {after == files}",
                   "exit 0, then exit 2 and every output byte-identical", (), t0)


# ------------------------------------------------------------------------------------------
# Fuzzing the stage reader (hypothesis strategies; the properties are plain functions)
# ------------------------------------------------------------------------------------------

def fuzz_base_text(folder: Path) -> str:
    """The text of a stage using most of what the reader reads: mesh parts with gprim and
    UsdShade materials, a closed glass part, implicit gprims, a point instancer, shaped and
    intensity-driven lights under transforms."""
    stage = _base_stage(folder / "fuzz_base.usda")
    p, f = box((-0.05, -0.05, -0.1), (0.05, 0.05, -0.08))
    add_mesh(stage, "/Luminaire/Lens", p, f, 1.0, "dielectric", ior=1.5, transmittance=0.9)
    UsdGeom.Cylinder.Define(stage, "/Luminaire/Post").CreateRadiusAttr(0.01)
    instancer = UsdGeom.PointInstancer.Define(stage, "/Luminaire/Screws")
    UsdGeom.Sphere.Define(stage, "/Luminaire/Screws/Head").CreateRadiusAttr(0.003)
    instancer.CreatePrototypesRel().SetTargets([Sdf.Path("/Luminaire/Screws/Head")])
    instancer.CreateProtoIndicesAttr([0, 0])
    instancer.CreatePositionsAttr([Gf.Vec3f(0.05, 0, -0.2), Gf.Vec3f(-0.05, 0, -0.2)])
    rect = UsdLux.RectLight.Define(stage, "/Luminaire/Panel")
    rect.CreateWidthAttr(0.02)
    rect.CreateHeightAttr(0.01)
    rect.CreateIntensityAttr(5000.0)
    rect.AddRotateXYZOp().Set(Gf.Vec3f(10.0, 0.0, 5.0))
    bulb = add_sphere_light(stage, "/Luminaire/Bulb", 0.005, translate=(0.0, 0.05, -0.05))
    shaping = UsdLux.ShapingAPI.Apply(bulb.GetPrim())
    shaping.CreateShapingConeAngleAttr(60.0)
    shaping.CreateShapingConeSoftnessAttr(0.2)
    shaping.CreateShapingFocusAttr(2.0)
    return stage.GetRootLayer().ExportToString()


#: Values a mutation may put in place of a number or a quoted token.
FUZZ_NUMBERS = ("nan", "-nan", "inf", "-inf", "0", "-0", "1", "-1", "0.5", "1.5", "1e38",
                "-1e38", "3.5e38", "1e-45", "1e-300", "1e300", "2147483648", "-2147483649",
                "9223372036854775808", "1e", "0x10", "")
FUZZ_TOKENS = ('"shiny"', '""', '"X"', '"W"', '"leftHanded"', '"invisible"', '"guide"',
               '"proxy"', '"dielectric"', '"mirror"', '"absorber"', '"translucent"',
               '"glossy"', '"catmullClark"', '"\\u0000"', "'", '"a" "b"')

_NUMBER = __import__("re").compile(r"(?<![\w.])-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")
_QUOTED = __import__("re").compile(r'"[^"\n]*"')


def mutations():
    """Hypothesis strategy: a list of 1-4 text mutations of a stage."""
    from hypothesis import strategies as st

    index = st.integers(min_value=0, max_value=10 ** 6)
    op = st.one_of(
        st.tuples(st.just("number"), index, st.sampled_from(FUZZ_NUMBERS)),
        st.tuples(st.just("token"), index, st.sampled_from(FUZZ_TOKENS)),
        st.tuples(st.just("delete line"), index),
        st.tuples(st.just("duplicate line"), index),
        st.tuples(st.just("swap lines"), index, index),
        st.tuples(st.just("truncate"), st.floats(0.0, 1.0)),
        st.tuples(st.just("insert"), index, st.binary(min_size=1, max_size=8)),
    )
    return st.lists(op, min_size=1, max_size=4)


def mutate(text: str, ops) -> bytes:
    """Apply mutations from :func:`mutations` to a stage's text."""
    for op in ops:
        kind = op[0]
        lines = text.split("\n")
        if kind in ("number", "token"):
            found = list((_NUMBER if kind == "number" else _QUOTED).finditer(text))
            if found:
                m = found[op[1] % len(found)]
                text = text[:m.start()] + op[2] + text[m.end():]
        elif kind == "delete line":
            del lines[op[1] % len(lines)]
            text = "\n".join(lines)
        elif kind == "duplicate line":
            i = op[1] % len(lines)
            lines.insert(i, lines[i])
            text = "\n".join(lines)
        elif kind == "swap lines":
            i, j = op[1] % len(lines), op[2] % len(lines)
            lines[i], lines[j] = lines[j], lines[i]
            text = "\n".join(lines)
        elif kind == "truncate":
            text = text[:int(op[1] * len(text))]
        else:
            i = op[1] % (len(text) + 1)
            text = text[:i] + op[2].decode("latin-1") + text[i:]
    return text.encode("utf-8", "surrogateescape")


def check_scene(scene: Scene, photons: int = 64) -> None:
    """What every scene the reader returns must satisfy, and a few photons traced through
    it: finite values, valid materials and emitters, exact bookkeeping, finite rays."""
    from lumitrace.schema import SCATTERING_TOKENS

    assert np.isfinite(scene.triangles).all(), "non-finite triangles"
    assert scene.triangles.shape[1:] == (3, 3)
    n_mat = len(scene.materials)
    assert scene.material_index.size == 0 or (0 <= scene.material_index.min()
                                              and scene.material_index.max() < n_mat)
    for m in scene.materials:
        assert m.scattering in SCATTERING_TOKENS
        for v in (m.reflectance, m.specular_reflectance, m.transmittance, m.roughness):
            assert 0.0 <= v <= 1.0, m
        assert math.isfinite(m.ior) and m.ior > 0.0, m
    assert scene.emitters
    for e in scene.emitters:
        assert math.isfinite(e.flux) and e.flux > 0.0, e
        assert np.isfinite(e.to_world).all(), e
    r = trace(scene, photons, resolution=4, max_depth=64)
    assert r.balanced and r.finite, r.fractions()


def read_or_refuse(path: Path) -> str:
    """Read a stage: it must either give a sound scene or a StageError. Returns what
    happened ("scene", or the error's first words)."""
    import warnings

    from lumitrace.errors import StageError

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # NaN or overflow on the way: a bug
        try:
            scene = read_stage(path)
        except StageError as exc:
            message = str(exc)
            assert message and "\n" not in message, repr(message)
            return "StageError"
        check_scene(scene)
    return "scene"


def stage_values():
    """Hypothesis strategy: attribute edits (prim, attribute, value) of the fuzz stage,
    every value of the attribute's own type but anything in it."""
    from hypothesis import strategies as st

    f32 = st.floats(width=32)
    f64 = st.floats()
    vec3 = st.tuples(f32, f32, f32)
    small = st.integers(min_value=-3, max_value=12)
    edits = st.one_of(
        st.tuples(st.just(("/Luminaire/Box", "points")), st.lists(vec3, min_size=0, max_size=10)),
        st.tuples(st.just(("/Luminaire/Box", "faceVertexCounts")), st.lists(small, max_size=8)),
        st.tuples(st.just(("/Luminaire/Box", "faceVertexIndices")), st.lists(small, max_size=30)),
        st.tuples(st.just(("/Luminaire/Part", "xformOp:translate")), st.tuples(f64, f64, f64)),
        st.tuples(st.just(("/Luminaire/Panel", "xformOp:rotateXYZ")), vec3),
        st.tuples(st.sampled_from([("/Luminaire/Box", n) for n in (
            "lumitrace:reflectance", "lumitrace:specularReflectance",
            "lumitrace:transmittance", "lumitrace:roughness", "lumitrace:ior")] + [
            ("/Luminaire/Lens", "lumitrace:ior"), ("/Luminaire/Looks/Paint", "lumitrace:reflectance"),
            ("/Luminaire/Led", "inputs:radius"), ("/Luminaire/Led", "lumitrace:luminousFlux"),
            ("/Luminaire/Panel", "inputs:intensity"), ("/Luminaire/Panel", "inputs:exposure"),
            ("/Luminaire/Panel", "inputs:width"), ("/Luminaire/Bulb", "inputs:shaping:cone:angle"),
            ("/Luminaire/Bulb", "inputs:shaping:cone:softness"),
            ("/Luminaire/Bulb", "inputs:shaping:focus"), ("/Luminaire/Bulb", "inputs:radius")]),
            f32),
        st.tuples(st.sampled_from([("/Luminaire/Post", "radius"), ("/Luminaire/Post", "height"),
                                   ("/Luminaire/Screws/Head", "radius")]), f64),
        st.tuples(st.sampled_from([("/Luminaire/Box", "lumitrace:scattering"),
                                   ("/Luminaire/Lens", "lumitrace:scattering"),
                                   ("/Luminaire/Box", "orientation"), ("/Luminaire/Post", "axis"),
                                   ("/Luminaire/Box", "visibility"), ("/Luminaire/Part", "purpose")]),
                  st.sampled_from([t.strip('"') for t in FUZZ_TOKENS] + ["diffuse", "rightHanded", "Z"])),
        st.tuples(st.just(("/Luminaire/Screws", "positions")), st.lists(vec3, max_size=3)),
        st.tuples(st.just(("/Luminaire/Screws", "protoIndices")), st.lists(small, max_size=3)),
        st.tuples(st.just(("", "metersPerUnit")), f64),
    )
    return st.lists(edits, min_size=1, max_size=4)


def apply_values(stage: Usd.Stage, edits) -> None:
    """Set the edits of :func:`stage_values` on an open stage."""
    for (prim_path, name), value in edits:
        if name == "metersPerUnit":
            stage.SetMetadata("metersPerUnit", value)
            continue
        prim = stage.GetPrimAtPath(prim_path)
        attr = prim.GetAttribute(name)
        if name == "xformOp:rotateXYZ" or name == "xformOp:translate":
            if not attr:
                continue
            attr.Set(Gf.Vec3f(*value) if name == "xformOp:rotateXYZ" else Gf.Vec3d(*value))
        elif name in ("points", "positions"):
            prim.GetAttribute(name).Set([Gf.Vec3f(*v) for v in value])
        elif name in ("faceVertexCounts", "faceVertexIndices", "protoIndices"):
            prim.GetAttribute(name).Set(list(value))
        else:
            if not attr:  # shaping and intensity inputs may not be authored yet
                type_name = Sdf.ValueTypeNames.Token if isinstance(value, str) else \
                    Sdf.ValueTypeNames.Float
                attr = prim.CreateAttribute(name, type_name)
            attr.Set(value)


class quiet_usd:  # noqa: N801 - used as a context manager, like contextlib's
    """Collect, and drop, USD's warnings while building broken stages."""

    def __enter__(self):
        from pxr import UsdUtils

        self._delegate = UsdUtils.CoalescingDiagnosticDelegate()
        return self

    def __exit__(self, *exc):
        self._delegate = None
