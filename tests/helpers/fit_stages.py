"""Small stages for the fit's tests and tools: the reference mirror cup with its wall placed
by a translate op and its reflectance given, and a revolved profile reflector around a
small source, its mesh made from its profile."""
from __future__ import annotations

from pathlib import Path

from helpers.paths import REFERENCE

#: The profile reflector's true points (r, z) in metres: a cup opening downward from the
#: source's height.
PROFILE_POINTS = ((0.004, 0.004), (0.010, -0.002), (0.016, -0.010), (0.021, -0.020),
                  (0.025, -0.032))


def mirror_cup(path: Path, reflectance: float = 0.95, wall_z: float | None = None) -> Path:
    """The reference mirror cup at ``path``, its mirror's reflectance ``reflectance`` and,
    with ``wall_z``, its wall moved along the axis by a translate op (m)."""
    from pxr import Gf, Usd, UsdGeom

    text = (REFERENCE / "mirror_cup.usda").read_text()
    path.write_text(text.replace("float lumitrace:specularReflectance = 0.95",
                                 f"float lumitrace:specularReflectance = {reflectance!r}"))
    if wall_z is not None:
        stage = Usd.Stage.Open(str(path))
        UsdGeom.Xformable(stage.GetPrimAtPath("/Luminaire/Wall")).AddTranslateOp().Set(
            Gf.Vec3d(0.0, 0.0, wall_z))
        stage.GetRootLayer().Save()
    return path


def finished_cup(path: Path, finish: str = "mirror", flux: float = 1000.0) -> Path:
    """The mirror cup whose wall's finish is a variant set on the luminaire, ``finish``
    selected: ``mirror`` (specular 0.95), ``white`` (diffuse 0.8) or ``black`` (an
    absorber), each variant binding the wall to its material; its source of ``flux`` lm."""
    from pxr import Usd, UsdShade

    mirror_cup(path)
    stage = Usd.Stage.Open(str(path))
    root = stage.GetRootLayer()
    wall = root.GetPrimAtPath("/Luminaire/Wall")
    wall.RemoveProperty(wall.relationships["material:binding"])
    for name, scattering, attr, value in (("White", "diffuse", "reflectance", 0.8),
                                          ("Black", "absorber", None, None)):
        mat = UsdShade.Material.Define(stage, f"/Luminaire/Materials/{name}")
        mat.GetPrim().ApplyAPI("LumitraceMaterialAPI")
        mat.GetPrim().GetAttribute("lumitrace:scattering").Set(scattering)
        if attr:
            mat.GetPrim().GetAttribute(f"lumitrace:{attr}").Set(value)
    stage.GetPrimAtPath("/Luminaire/Source").GetAttribute("lumitrace:luminousFlux").Set(
        float(flux))
    vset = stage.GetPrimAtPath("/Luminaire").GetVariantSets().AddVariantSet("finish")
    for variant, material in (("mirror", "Mirror"), ("white", "White"), ("black", "Black")):
        vset.AddVariant(variant)
        vset.SetVariantSelection(variant)
        with vset.GetVariantEditContext():
            UsdShade.MaterialBindingAPI.Apply(stage.GetPrimAtPath("/Luminaire/Wall")).Bind(
                UsdShade.Material(stage.GetPrimAtPath(f"/Luminaire/Materials/{material}")))
    vset.SetVariantSelection(finish)
    root.Save()
    return path


def profile_reflector(path: Path, points=PROFILE_POINTS, reflectance: float = 0.9,
                      segments: int = 48, source_radius: float = 0.001,
                      roughness: float | None = None) -> Path:
    """A revolved mirror profile (``points``, (r, z) m; glossy with ``roughness``) around
    a spherical source of ``source_radius`` m and 1000 lm at the origin, Z up, metres; its
    mesh made from its profile as lumitrace writes it."""
    from pxr import Gf, Usd, UsdGeom, UsdLux, UsdShade, Vt

    from lumitrace.delta.profile import write_profile_mesh

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    lum = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(lum.GetPrim())
    mat = UsdShade.Material.Define(stage, "/Luminaire/Materials/Mirror")
    mat.GetPrim().ApplyAPI("LumitraceMaterialAPI")
    mat.GetPrim().GetAttribute("lumitrace:scattering").Set(
        "mirror" if roughness is None else "glossy")
    mat.GetPrim().GetAttribute("lumitrace:specularReflectance").Set(reflectance)
    if roughness is not None:
        mat.GetPrim().GetAttribute("lumitrace:roughness").Set(roughness)
    mesh = UsdGeom.Mesh.Define(stage, "/Luminaire/Reflector")
    prim = mesh.GetPrim()
    prim.ApplyAPI("LumitraceProfileAPI")
    prim.GetAttribute("lumitrace:profile:points").Set(
        Vt.Vec2fArray([Gf.Vec2f(float(r), float(z)) for r, z in points]))
    prim.GetAttribute("lumitrace:profile:segments").Set(segments)
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(mat)
    write_profile_mesh(prim)
    light = UsdLux.SphereLight.Define(stage, "/Luminaire/Source")
    light.CreateRadiusAttr(source_radius)
    light.GetPrim().ApplyAPI("LumitraceEmitterAPI")
    light.GetPrim().GetAttribute("lumitrace:luminousFlux").Set(1000.0)
    stage.GetRootLayer().Save()
    return path


def mirror_cup_target(folder: Path, reflectance: float = 0.95,
                      photons: int = 1_000_000) -> Path:
    """The LDT of the mirror cup at ``reflectance``, traced with ``photons`` and a seed no
    fit uses (99), written in ``folder``: a fit's target."""
    from lumitrace.publish.outputs import write_outputs
    from lumitrace.run.session import run
    from lumitrace.run.settings import TraceSettings
    from lumitrace.stage.reader import read_stage

    truth = mirror_cup(Path(folder) / "truth.usda", reflectance)
    result = run(read_stage(truth), TraceSettings(photons=photons, seed=99, threads=2))
    return Path(write_outputs(result, Path(folder) / "target", sublayer=False,
                              pictures=False)["ldt"])
