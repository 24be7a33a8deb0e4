#!/usr/bin/env python
"""Write the reference stages (``stages/reference/*.usda``) and the demo stage
(``stages/downlight.usda``).

Every reference stage stores its analytic expectation in its root layer's customLayerData
under ``lumitrace:expectation`` (read it with ``lumitrace.report.references.read_expectation``).
Geometric figures that depend on the tessellation (port area fraction, mirror solid angle,
beam spread) are computed here from the very triangles written to the stage.

Usage::

    python tools/make_stages.py            # (re)write the stages in stages/
    python tools/make_stages.py --check    # exit 1 if a committed stage is out of date
    python tools/make_stages.py --out DIR  # write them somewhere else

The output is deterministic: running the script twice gives byte-identical files.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
try:
    import lumitrace  # noqa: F401  (registers the schema plugin when it is present)
except ImportError:  # running from a source checkout without installing the package
    sys.path.insert(0, str(ROOT / "service"))
from lumitrace.atomic import write_text  # noqa: E402
from lumitrace.report.references import EXPECTATION_KEY, lambertian_slab_flux  # noqa: E402
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt  # noqa: E402

FLUX = 1000.0  # lm, every reference emitter

# ------------------------------------------------------------------------------------------
# Stage building blocks
# ------------------------------------------------------------------------------------------


def new_stage(meters_per_unit: float, doc: str) -> tuple[Usd.Stage, Usd.Prim]:
    """An in-memory Z-up stage with the default prim ``/Luminaire`` (an Xform)."""
    stage = Usd.Stage.CreateInMemory("stage.usda")
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.GetRootLayer().documentation = doc
    lum = UsdGeom.Xform.Define(stage, "/Luminaire").GetPrim()
    Usd.ModelAPI(lum).SetKind("component")
    stage.SetDefaultPrim(lum)
    return stage, lum


def set_expectation(stage: Usd.Stage, expectation: dict) -> None:
    """Store the analytic expectation (numbers as doubles) in the root layer."""
    def conv(v):
        if isinstance(v, str):
            return v
        if isinstance(v, (tuple, list, np.ndarray)):
            v = [float(x) for x in v]
            return Gf.Vec3d(*v) if len(v) == 3 else Vt.DoubleArray(v)
        return float(v)
    for key in ("kind", "description", "flux"):
        assert key in expectation, key
    layer = stage.GetRootLayer()
    data = dict(layer.customLayerData)
    data[EXPECTATION_KEY] = {k: conv(v) for k, v in expectation.items()}
    layer.customLayerData = data


def add_emitter(light: UsdLux.BoundableLightBase, flux: float) -> None:
    """Apply LumitraceEmitterAPI with ``lumitrace:luminousFlux`` (lm)."""
    prim = light.GetPrim()
    prim.AddAppliedSchema("LumitraceEmitterAPI")
    prim.CreateAttribute("lumitrace:luminousFlux", Sdf.ValueTypeNames.Float,
                         custom=False).Set(float(flux))


def make_material(stage: Usd.Stage, name: str, scattering: str | None,
                  preview: dict | None = None, **props: float) -> UsdShade.Material:
    """A Material under /Luminaire/Materials with LumitraceMaterialAPI (if ``scattering``)
    and optionally a UsdPreviewSurface shader (``preview``: input name -> value)."""
    UsdGeom.Scope.Define(stage, "/Luminaire/Materials")
    mat = UsdShade.Material.Define(stage, f"/Luminaire/Materials/{name}")
    prim = mat.GetPrim()
    if scattering is not None:
        prim.AddAppliedSchema("LumitraceMaterialAPI")
        prim.CreateAttribute("lumitrace:scattering", Sdf.ValueTypeNames.Token,
                             custom=False).Set(scattering)
        names = {"reflectance": "reflectance", "specular_reflectance": "specularReflectance",
                 "transmittance": "transmittance", "ior": "ior", "roughness": "roughness"}
        for key, value in props.items():
            prim.CreateAttribute(f"lumitrace:{names[key]}", Sdf.ValueTypeNames.Float,
                                 custom=False).Set(float(value))
    else:
        assert not props
    if preview:
        shader = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild("PreviewSurface"))
        shader.CreateIdAttr("UsdPreviewSurface")
        for key, value in preview.items():
            if isinstance(value, tuple):
                shader.CreateInput(key, Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*value))
            else:
                shader.CreateInput(key, Sdf.ValueTypeNames.Float).Set(float(value))
        mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return mat


def bind(prim: Usd.Prim, material: UsdShade.Material) -> None:
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)


def orient(points: np.ndarray, tris: np.ndarray,
           desired: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """Reorder each triangle so that its counter-clockwise normal points along
    ``desired(centroids)`` (T, 3); checks that no triangle is degenerate."""
    tris = np.array(tris, dtype=np.int64)
    p = points[tris].astype(np.float64)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area2 = np.linalg.norm(n, axis=1)
    assert area2.min() > 0, "degenerate triangle"
    want = desired(p.mean(axis=1))
    dots = np.einsum("ij,ij->i", n, want) / area2 / np.linalg.norm(want, axis=1)
    assert np.abs(dots).min() > 1e-6, "triangle edge-on to its desired normal"
    flip = dots < 0
    tris[flip] = tris[flip][:, [0, 2, 1]]
    return tris


def define_mesh(stage: Usd.Stage, path: str, points: np.ndarray, tris: np.ndarray,
                material: UsdShade.Material | None = None) -> UsdGeom.Mesh:
    """A triangle mesh (no subdivision) with its extent, optionally bound to a material."""
    mesh = UsdGeom.Mesh.Define(stage, path)
    pts = np.asarray(points, dtype=np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(tris)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for i in np.ravel(tris)]))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    used = pts[np.unique(np.ravel(tris))]
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, used.min(axis=0))),
                                         Gf.Vec3f(*map(float, used.max(axis=0)))]))
    if material is not None:
        bind(mesh.GetPrim(), material)
    return mesh


def triangle_areas(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Areas of the triangles as stored (float32 points), in float64."""
    p = np.asarray(points, dtype=np.float32).astype(np.float64)[tris]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def grid_triangles(rows: int, cols: int, offset: int = 0) -> list[tuple[int, int, int]]:
    """Two triangles per quad of a (rows+1) x cols vertex grid, periodic along cols."""
    tris = []
    for i in range(rows):
        for j in range(cols):
            a = offset + i * cols + j
            b = offset + i * cols + (j + 1) % cols
            c = offset + (i + 1) * cols + (j + 1) % cols
            d = offset + (i + 1) * cols + j
            tris += [(a, b, c), (a, c, d)]
    return tris


def prism(radius: float, z0: float, z1: float, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed regular ``segments``-gon prism (vertices at ``radius``) with outward normals."""
    phi = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.stack([radius * np.cos(phi), radius * np.sin(phi)], axis=1)
    pts = np.concatenate([np.c_[ring, np.full(segments, z0)], np.c_[ring, np.full(segments, z1)],
                          [[0.0, 0.0, z0], [0.0, 0.0, z1]]])
    c0, c1 = 2 * segments, 2 * segments + 1
    tris = grid_triangles(1, segments)
    for j in range(segments):
        k = (j + 1) % segments
        tris += [(c0, j, k), (c1, segments + j, segments + k)]
    centre = np.array([0.0, 0.0, 0.5 * (z0 + z1)])
    return pts, orient(pts, np.array(tris), lambda c: _outward_prism(c, centre, z0, z1))


def _outward_prism(c: np.ndarray, centre: np.ndarray, z0: float, z1: float) -> np.ndarray:
    out = c - centre
    cap = np.isclose(c[:, 2], z0) | np.isclose(c[:, 2], z1)
    out[~cap, 2] = 0.0
    out[cap, :2] = 0.0
    return out


# ------------------------------------------------------------------------------------------
# Reference stages
# ------------------------------------------------------------------------------------------


def isotropic() -> Usd.Stage:
    stage, _ = new_stage(1.0, "Reference: an isotropic point-like source (SphereLight, "
                              "radius 1 mm, 1000 lm), no geometry.")
    light = UsdLux.SphereLight.Define(stage, "/Luminaire/Source")
    light.CreateRadiusAttr(0.001)
    add_emitter(light, FLUX)
    set_expectation(stage, {
        "kind": "isotropic",
        "description": "A 1000 lm sphere source radiates the same intensity in every "
                       "direction: I = Phi / (4 pi) = 1000 / (4 pi) cd.",
        "flux": FLUX,
        "intensity_cd": FLUX / (4 * math.pi),
        "source_radius": 0.001,
    })
    return stage


def _lambertian_source(stage: Usd.Stage) -> None:
    light = UsdLux.DiskLight.Define(stage, "/Luminaire/Source")
    light.CreateRadiusAttr(0.05)
    add_emitter(light, FLUX)  # identity transform: emits along -Z (down)


def lambertian_disc() -> Usd.Stage:
    stage, _ = new_stage(1.0, "Reference: a one-sided Lambertian DiskLight (radius 5 cm, "
                              "1000 lm) at the origin emitting downward, no geometry.")
    _lambertian_source(stage)
    set_expectation(stage, {
        "kind": "lambertian",
        "description": "A one-sided Lambertian disc of flux Phi emitting along -Z gives "
                       "I(gamma) = (Phi / pi) cos(gamma) for gamma < 90 deg from the axis "
                       "(0, 0, -1) and 0 beyond, peak 1000 / pi cd.",
        "flux": FLUX,
        "axis": (0.0, 0.0, -1.0),
        "peak_cd": FLUX / math.pi,
        "source_radius": 0.05,
    })
    return stage


def integrating_sphere() -> Usd.Stage:
    R, rho = 0.1, 0.9                 # m, diffuse reflectance
    n_lon, n_lat, port_bands = 192, 96, 12
    stage, _ = new_stage(1.0, "Reference: a diffuse integrating sphere (radius 0.1 m, "
                              "reflectance 0.9) with a port around -Z and a shielded "
                              "inner DiskLight at the +Z pole facing the wall.")
    # UV sphere, polar angle theta from +Z; bands i = 0 .. n_lat-1, vertex rings 1 .. n_lat-1.
    theta = np.pi * np.arange(1, n_lat) / n_lat
    phi = 2 * np.pi * np.arange(n_lon) / n_lon
    rings = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                      np.outer(np.cos(theta), np.ones(n_lon))], axis=-1).reshape(-1, 3) * R
    pts = np.concatenate([rings, [[0, 0, R], [0, 0, -R]]]).astype(np.float32)
    north, south = len(rings), len(rings) + 1
    tris_all = []
    band = []   # band index of each triangle
    for j in range(n_lon):
        tris_all.append((north, j, (j + 1) % n_lon)); band.append(0)
    for i, t in enumerate(grid_triangles(n_lat - 2, n_lon)):
        tris_all.append(t); band.append(1 + i // (2 * n_lon))
    last = (n_lat - 2) * n_lon
    for j in range(n_lon):
        tris_all.append((south, last + j, last + (j + 1) % n_lon)); band.append(n_lat - 1)
    tris_all = orient(pts.astype(np.float64), np.array(tris_all), lambda c: -c)  # inward
    band = np.array(band)
    areas = triangle_areas(pts, tris_all)
    keep = band < n_lat - port_bands
    port_fraction = float(areas[~keep].sum() / areas.sum())
    port_half_angle = np.pi * port_bands / n_lat               # around -Z
    port_fraction_smooth = float((1 - math.cos(port_half_angle)) / 2)
    # Drop the cap's triangles and the vertices only they use; the port rim is vertex ring
    # n_lat - port_bands (polar angle 180 - 22.5 deg).
    tris = tris_all[keep]
    used = np.unique(tris)
    remap = -np.ones(len(pts), dtype=np.int64)
    remap[used] = np.arange(len(used))
    pts, tris = pts[used], remap[tris]
    wall = make_material(stage, "Wall", "diffuse", reflectance=rho)
    define_mesh(stage, "/Luminaire/Sphere", pts, tris, wall)

    disk_radius, disk_z = 0.005, R - 0.005
    # The disk must lie inside the faceted sphere: every facet plane is farther than this.
    p = pts.astype(np.float64)[tris]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    plane_dist = np.einsum("ij,ij->i", -nrm, p[:, 0])           # distance of facet planes
    assert plane_dist.min() > math.hypot(disk_radius, disk_z) + 1e-3
    light = UsdLux.DiskLight.Define(stage, "/Luminaire/Source")
    light.CreateRadiusAttr(disk_radius)
    light.AddTranslateOp().Set(Gf.Vec3d(0, 0, disk_z))
    light.AddRotateXOp().Set(180.0)       # local -Z -> world +Z: faces the wall, not the port
    add_emitter(light, FLUX)

    def escaped(f: float) -> float:
        return FLUX * rho * f / (1 - rho * (1 - f))
    set_expectation(stage, {
        "kind": "integrating_sphere",
        "description": "The flux leaving the port of a diffuse sphere of reflectance rho and "
                       "port area fraction f, lit by a source shielded from the port, is "
                       "Phi_out = Phi rho f / (1 - rho (1 - f)).",
        "flux": FLUX,
        "reflectance": rho,
        "port_fraction": port_fraction,
        "port_fraction_smooth": port_fraction_smooth,
        "escaped_flux": escaped(port_fraction),
        "escaped_flux_smooth": escaped(port_fraction_smooth),
        "port_axis": (0.0, 0.0, -1.0),
        "port_half_angle_deg": math.degrees(port_half_angle),
        "sphere_radius": R,
        "segments": (float(n_lon), float(n_lat)),
    })
    return stage


def fresnel_slab() -> Usd.Stage:
    n, half, top, thick = 1.5, 20.0, -0.01, 0.01
    stage, _ = new_stage(1.0, "Reference: the Lambertian disc (radius 5 cm, 1000 lm, "
                              "emitting down) above a clear glass slab (n = 1.5, 1 cm thick, "
                              "top face at z = -1 cm, 40 m wide).")
    _lambertian_source(stage)
    corners = np.array([[x, y, z] for z in (top - thick, top) for y in (-half, half)
                        for x in (-half, half)])
    faces = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    tris = np.array([t for a, b, c, d in faces for t in ((a, b, c), (a, c, d))])
    centre = np.array([0.0, 0.0, top - thick / 2])

    def outward(c: np.ndarray) -> np.ndarray:
        d = (c - centre) / np.array([half, half, thick / 2])
        return np.where(np.abs(d) == np.abs(d).max(axis=1, keepdims=True), np.sign(d), 0.0)
    tris = orient(corners, tris, outward)
    glass = make_material(stage, "Glass", "dielectric", ior=n, transmittance=1.0)
    define_mesh(stage, "/Luminaire/Slab", corners, tris, glass)
    t_flux, r_flux = lambertian_slab_flux(n)
    set_expectation(stage, {
        "kind": "fresnel_slab",
        "description": "A Lambertian disc of flux Phi above a clear non-absorbing slab of "
                       "index n gives I(gamma) = (Phi / pi) cos(gamma) T(gamma) below and "
                       "(Phi / pi) cos(gamma') (1 - T(gamma')) above (gamma' from the zenith), "
                       "T = mean over s, p of (1 - r) / (1 + r), r the Fresnel reflectance "
                       "of one face.",
        "flux": FLUX,
        "ior": n,
        "axis": (0.0, 0.0, -1.0),
        "peak_cd": FLUX / math.pi,
        "normal_transmittance": 2 * n / (n * n + 1),
        "transmitted_flux": FLUX * t_flux,
        "reflected_flux": FLUX * r_flux,
        "slab_top_z": top,
        "slab_thickness": thick,
        "slab_half_width": half,
        "max_gamma_deg": 89.9,
    })
    return stage


def _triangle_solid_angles(p: np.ndarray) -> np.ndarray:
    """Solid angles (sr) of triangles (T, 3, 3) seen from the origin (Van Oosterom-Strackee)."""
    a, b, c = p[:, 0], p[:, 1], p[:, 2]
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    num = np.abs(np.einsum("ij,ij->i", a, np.cross(b, c)))
    den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb
           + np.einsum("ij,ij->i", b, c) * la)
    return 2.0 * np.arctan2(num, den)


def paraboloid() -> Usd.Stage:
    f, rim, rho, src = 0.02, 0.05, 0.95, 0.0005      # m, m, -, m
    n_seg, n_ring = 256, 64
    stage, _ = new_stage(1.0, "Reference: a small SphereLight (radius 0.5 mm, 1000 lm) at "
                              "the focus of a mirror paraboloid (focal length 2 cm, rim "
                              "radius 5 cm, specular reflectance 0.95) opening downward.")
    # Surface z = f - r^2 / (4 f): vertex above the focus (origin), opening towards -Z.
    # Rings evenly spaced in the surface normal's tilt psi = atan(r / 2f), so every ring of
    # facets bends the beam by about the same small angle.
    psi = np.linspace(0.0, math.atan(rim / (2 * f)), n_ring + 1)[1:]
    r = 2 * f * np.tan(psi)
    r[-1] = rim
    phi = 2 * np.pi * np.arange(n_seg) / n_seg
    rings = np.stack([np.outer(r, np.cos(phi)), np.outer(r, np.sin(phi)),
                      np.outer(f - r * r / (4 * f), np.ones(n_seg))], axis=-1).reshape(-1, 3)
    pts = np.concatenate([rings, [[0.0, 0.0, f]]]).astype(np.float32)
    apex = len(rings)
    tris = [(apex, j, (j + 1) % n_seg) for j in range(n_seg)]
    tris += grid_triangles(n_ring - 1, n_seg)
    p64 = pts.astype(np.float64)
    tris = orient(p64, np.array(tris), lambda c: -c)          # normals toward the focus
    mirror = make_material(stage, "Mirror", "mirror", specular_reflectance=rho)
    define_mesh(stage, "/Luminaire/Mirror", pts, tris, mirror)
    light = UsdLux.SphereLight.Define(stage, "/Luminaire/Source")
    light.CreateRadiusAttr(src)
    add_emitter(light, FLUX)

    # Opening half-angle around -Z seen from the focus, and the flux fraction on the mirror.
    rim_z = f - rim * rim / (4 * f)
    opening = math.atan2(rim, -rim_z)
    p = p64[tris]
    fraction = float(_triangle_solid_angles(p).sum() / (4 * math.pi))
    fraction_smooth = (1 + math.cos(opening)) / 2
    # Beam spread: for points q on every facet (a barycentric grid), the ray from the focus
    # reflected by the facet, plus the source's angular radius seen from q (a mirror turns a
    # cone of incident directions into a cone of the same angle).
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    k = 8
    bary = np.array([(i, j, k - i - j) for i in range(k + 1) for j in range(k + 1 - i)]) / k
    q = np.einsum("bk,tkj->tbj", bary, p)                      # (T, B, 3)
    dist = np.linalg.norm(q, axis=2)
    u = q / dist[..., None]
    v = u - 2 * np.einsum("tbj,tj->tb", u, nrm)[..., None] * nrm[:, None, :]
    dev = np.degrees(np.arccos(np.clip(-v[..., 2], -1, 1)))
    spread = dev + np.degrees(np.arcsin(src / dist))
    beam_half_angle = math.ceil(2 * float(spread.max())) / 2 + 0.5     # margin, 0.5 deg steps
    set_expectation(stage, {
        "kind": "paraboloid",
        "description": "A source of flux Phi at the focus of a mirror paraboloid of "
                       "reflectance rho sends a beam of Phi F rho (F the fraction of its flux "
                       "on the mirror, 1 - F = (1 - cos opening) / 2) within a few degrees of "
                       "-Z and I = Phi / (4 pi) cd directly through the opening.",
        "flux": FLUX,
        "focal_length": f,
        "rim_radius": rim,
        "source_radius": src,
        "specular_reflectance": rho,
        "axis": (0.0, 0.0, -1.0),
        "opening_half_angle_deg": math.degrees(opening),
        "direct_cd": FLUX / (4 * math.pi),
        "mirror_flux_fraction": fraction,
        "mirror_flux_fraction_smooth": fraction_smooth,
        "beam_flux": FLUX * fraction * rho,
        "direct_flux": FLUX * (1 - fraction),
        "beam_half_angle_deg": beam_half_angle,
        "beam_spread_max_deg": float(spread.max()),
    })
    return stage


# ------------------------------------------------------------------------------------------
# Demo: a recessed downlight, modelled in millimetres
# ------------------------------------------------------------------------------------------


def downlight() -> Usd.Stage:
    stage, lum = new_stage(0.001, "Demo: a recessed LED downlight modelled in millimetres "
                                  "(LED board, faceted glossy reflector, opal diffuser, dark "
                                  "housing); 1200 lm.")
    board_mat = make_material(stage, "BoardWhite", "diffuse", reflectance=0.8,
                              preview={"diffuseColor": (0.8, 0.8, 0.8), "roughness": 0.8})
    refl_mat = make_material(stage, "ReflectorAluminium", "glossy",
                             specular_reflectance=0.92, roughness=0.15,
                             preview={"diffuseColor": (0.92, 0.92, 0.92), "metallic": 1.0,
                                      "roughness": 0.15})
    diff_mat = make_material(stage, "DiffuserOpal", "translucent", reflectance=0.25,
                             transmittance=0.65,
                             preview={"diffuseColor": (0.9, 0.9, 0.9)})
    # No lumitrace API: the reader falls back to the UsdPreviewSurface inputs.
    housing_mat = make_material(stage, "HousingPaint", None,
                                preview={"diffuseColor": (0.05, 0.05, 0.05),
                                         "roughness": 0.6})

    # LED: 20 x 20 mm, 0.5 mm below the board, emitting down.
    led = UsdLux.RectLight.Define(stage, "/Luminaire/LED")
    led.CreateWidthAttr(20.0)
    led.CreateHeightAttr(20.0)
    led.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 49.5))
    add_emitter(led, 1200.0)

    # Board: a 1.6 mm PCB disc whose underside (z = 50) closes the reflector's top.
    pts, tris = prism(27.0, 50.0, 51.6, 48)
    define_mesh(stage, "/Luminaire/Board", pts, tris, board_mat)

    # Reflector: 24 facets around, 3 rows down a flaring profile from r = 25 mm at the
    # board (z = 50) to r = 60 mm at the opening (z = 0); normals face the axis.
    facets = 24
    radii = np.array([25.0, 39.0, 51.0, 60.0])
    heights = np.array([50.0, 100.0 / 3.0, 50.0 / 3.0, 0.0])
    phi = 2 * np.pi * np.arange(facets) / facets
    pts = np.stack([np.outer(radii, np.cos(phi)), np.outer(radii, np.sin(phi)),
                    np.outer(heights, np.ones(facets))], axis=-1).reshape(-1, 3)
    tris = orient(pts, np.array(grid_triangles(len(radii) - 1, facets)),
                  lambda c: -c * np.array([1.0, 1.0, 0.0]))
    define_mesh(stage, "/Luminaire/Reflector", pts, tris, refl_mat)

    # Diffuser: a 2 mm opal disc under the opening, covering the reflector's rim.
    pts, tris = prism(62.0, -2.0, 0.0, 48)
    define_mesh(stage, "/Luminaire/Diffuser", pts, tris, diff_mat)

    # Housing: a can of radius 64 mm from the trim (z = -2) to z = 75 with a top, and a
    # trim flange from the diffuser's edge (62 mm) out to 75 mm; normals face outward.
    seg = 48
    phi = 2 * np.pi * np.arange(seg) / seg
    cs, sn = np.cos(phi), np.sin(phi)
    wall_bottom = np.c_[64 * cs, 64 * sn, np.full(seg, -2.0)]
    wall_top = np.c_[64 * cs, 64 * sn, np.full(seg, 75.0)]
    flange_in = np.c_[62 * cs, 62 * sn, np.full(seg, -2.0)]
    flange_out = np.c_[75 * cs, 75 * sn, np.full(seg, -2.0)]
    pts = np.concatenate([wall_bottom, wall_top, flange_in, flange_out, [[0.0, 0.0, 75.0]]])
    tris = grid_triangles(1, seg)                               # wall
    tris += [(4 * seg, seg + j, seg + (j + 1) % seg) for j in range(seg)]   # top
    tris += grid_triangles(1, seg, offset=2 * seg)              # flange
    n_wall, n_top = 2 * seg, seg

    def outward(c: np.ndarray) -> np.ndarray:
        out = np.zeros_like(c)
        out[:n_wall, :2] = c[:n_wall, :2]
        out[n_wall:n_wall + n_top, 2] = 1.0
        out[n_wall + n_top:, 2] = -1.0
        return out
    tris = orient(pts, np.array(tris), outward)
    define_mesh(stage, "/Luminaire/Housing", pts, tris, housing_mat)
    return stage


def _box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """A closed box (12 triangles), normals outward."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    pts = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1])
                    for x in (lo[0], hi[0])])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [(a, b, c) for q in quads for (a, b, c) in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]
    centre = 0.5 * (lo + hi)
    return pts, orient(pts, np.array(tris), lambda c: c - centre)


def louvre() -> Usd.Stage:
    """A linear louvre luminaire with many parts: a 4 x 8 array of LED packages on a
    board, a specular louvre of 26 cross blades and 30 long blades (56 blades) below it,
    side reflectors and a housing; 4000 lm."""
    stage, lum = new_stage(0.001, "A louvre luminaire with many parts (for selective "
                                  "retracing): 32 LEDs over a 56-blade specular louvre, "
                                  "side reflectors, white board, dark housing; 4000 lm.")
    board = make_material(stage, "BoardWhite", "diffuse", reflectance=0.85)
    blade = make_material(stage, "LouvreSpecular", "glossy", specular_reflectance=0.9,
                          roughness=0.05)
    side = make_material(stage, "SideReflector", "mirror", specular_reflectance=0.92)
    housing = make_material(stage, "HousingPaint", "diffuse", reflectance=0.1)
    UsdGeom.Xform.Define(stage, "/Luminaire/LEDs")
    for i in range(4):
        for j in range(8):
            led = UsdLux.RectLight.Define(stage, f"/Luminaire/LEDs/LED_{i}_{j}")
            led.CreateWidthAttr(3.0)
            led.CreateHeightAttr(3.0)
            led.AddTranslateOp().Set(Gf.Vec3d(-105.0 + 30.0 * j, -45.0 + 30.0 * i, 39.5))
            add_emitter(led, 125.0)
    pts, tris = _box((-125.0, -62.0, 40.0), (125.0, 62.0, 41.6))
    define_mesh(stage, "/Luminaire/Board", pts, tris, board)
    UsdGeom.Xform.Define(stage, "/Luminaire/Louvre")
    k = 0
    for x in np.linspace(-120.0, 120.0, 26):  # cross blades, across the width
        pts, tris = _box((x - 0.4, -60.0, 0.0), (x + 0.4, 60.0, 30.0))
        define_mesh(stage, f"/Luminaire/Louvre/Blade_{k:02d}", pts, tris, blade)
        k += 1
    for y in np.linspace(-58.0, 58.0, 30):  # long blades, shallower, along the length
        pts, tris = _box((-120.0, y - 0.3, 0.0), (120.0, y + 0.3, 8.0))
        define_mesh(stage, f"/Luminaire/Louvre/Blade_{k:02d}", pts, tris, blade)
        k += 1
    for name, y in (("SideA", -61.0), ("SideB", 61.0)):
        pts, tris = _box((-125.0, y - 0.5, 0.0), (125.0, y + 0.5, 40.0))
        define_mesh(stage, f"/Luminaire/{name}", pts, tris, side)
    pts, tris = _box((-128.0, -66.0, 41.6), (128.0, 66.0, 50.0))
    define_mesh(stage, "/Luminaire/Housing", pts, tris, housing)
    return stage


def mirror_cup() -> Usd.Stage:
    radius, length, rho, src, n_seg = 0.025, 0.05, 0.95, 0.00005, 256  # m, m, -, m, -
    stage, _ = new_stage(1.0, "Reference: a one-sided Lambertian DiskLight (radius 0.05 mm, "
                              "1000 lm) on the axis of an open mirror cylinder (radius 25 mm, "
                              "50 mm long, specular reflectance 0.95) at its top rim, "
                              "emitting down into it.")
    phi = 2.0 * np.pi * np.arange(n_seg) / n_seg
    ring = np.stack([radius * np.cos(phi), radius * np.sin(phi)], axis=1)
    pts = np.concatenate([np.c_[ring, np.zeros(n_seg)], np.c_[ring, np.full(n_seg, -length)]])
    tris = orient(pts, np.array(grid_triangles(1, n_seg)),
                  lambda c: -np.c_[c[:, :2], np.zeros(len(c))])  # normals toward the axis
    mirror = make_material(stage, "Mirror", "mirror", specular_reflectance=rho)
    define_mesh(stage, "/Luminaire/Wall", pts.astype(np.float32), tris, mirror)
    light = UsdLux.DiskLight.Define(stage, "/Luminaire/Source")
    light.CreateRadiusAttr(src)
    add_emitter(light, FLUX)
    set_expectation(stage, {
        "kind": "mirror_cup",
        "description": "A Lambertian point source of flux Phi on the axis of an open mirror "
                       "cylinder of reflectance rho, at its rim, emitting into it: a ray at "
                       "gamma keeps gamma at every reflection off the vertical wall, so "
                       "I(gamma) = (Phi / pi) cos(gamma) rho^k(gamma), k the reflections "
                       "before it leaves (steps where tan(gamma) = (2k - 1) radius / length).",
        "flux": FLUX,
        "axis": (0.0, 0.0, -1.0),
        "peak_cd": FLUX / math.pi,
        "radius": radius,
        "length": length,
        "specular_reflectance": rho,
        "source_radius": src,
    })
    return stage


def warm_downlight() -> Usd.Stage:
    """The demo downlight in colour, open (no diffuser): a 3000 K phosphor LED (CIE
    LED-B2) and a champagne anodised reflector whose reflectance rises toward the red, so
    the light the reflector sends out is warmer than the LED's own."""
    stage = downlight()
    stage.GetRootLayer().documentation = (
        "Demo in colour: the recessed LED downlight without its diffuser, with a 3000 K "
        "phosphor-converted LED (CIE LED-B2) and a champagne anodised reflector (spectral "
        "reflectance 0.63 at 400 nm rising to 0.93 at 700 nm); 1200 lm.")
    stage.RemovePrim("/Luminaire/Diffuser")
    stage.RemovePrim("/Luminaire/Materials/DiffuserOpal")
    led = stage.GetPrimAtPath("/Luminaire/LED")
    led.CreateAttribute("lumitrace:illuminant", Sdf.ValueTypeNames.String).Set("LED-B2")
    refl = stage.GetPrimAtPath("/Luminaire/Materials/ReflectorAluminium")
    wl = np.arange(380.0, 781.0, 20.0)
    rho = 0.62 + 0.31 / (1.0 + np.exp(-(wl - 540.0) / 40.0))
    refl.CreateAttribute("lumitrace:specularSpectrum", Sdf.ValueTypeNames.Float2Array).Set(
        [Gf.Vec2f(float(a), float(round(b, 4))) for a, b in zip(wl, rho)])
    return stage


STAGES: dict[str, Callable[[], Usd.Stage]] = {
    "louvre.usda": louvre,
    "reference/isotropic.usda": isotropic,
    "reference/lambertian_disc.usda": lambertian_disc,
    "reference/integrating_sphere.usda": integrating_sphere,
    "reference/fresnel_slab.usda": fresnel_slab,
    "reference/paraboloid.usda": paraboloid,
    "reference/mirror_cup.usda": mirror_cup,
    "downlight.usda": downlight,
    "warm_downlight.usda": warm_downlight,
}


def render(name: str) -> str:
    """The text of one stage file."""
    stage = STAGES[name]()  # keep the stage alive while its root layer is exported
    return stage.GetRootLayer().ExportToString()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=ROOT / "stages",
                    help="folder to write into (default: the repository's stages/)")
    ap.add_argument("--check", action="store_true",
                    help="do not write; exit 1 if any file in --out differs from its script")
    ap.add_argument("names", nargs="*", metavar="NAME",
                    help="stages to write, relative to --out (default: all): "
                         + ", ".join(STAGES))
    args = ap.parse_args(argv)
    unknown = [n for n in args.names if n not in STAGES]
    if unknown:
        ap.error(f"unknown stage(s): {', '.join(unknown)}")
    stale = []
    for name in args.names or STAGES:
        text = render(name)
        path = args.out / name
        if args.check:
            if not path.exists() or path.read_text(encoding="utf-8") != text:
                stale.append(name)
            continue
        write_text(path, text)
        path.chmod(0o644)
        print(f"wrote {path}")
    if stale:
        print("out of date: " + ", ".join(stale), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
