"""The flat scene both sides speak: the stage reader builds it, the tracer only reads it.

Plain dataclasses of numpy arrays in SI units (metres, lumens) and the stage's own axes,
with the rules of emission shape (one-sided lights, the UsdLux shaping window) kept once.
"""
from .model import (ABSORBER, DIELECTRIC, DIFFUSE, EMITTER_KINDS, GLOSSY, MIRROR,
                    SCATTERING_MODELS, TRANSLUCENT, Emitter, IesShaping, LightGroup,
                    LuminaireInfo, Material, PartFrame, Scene, point_bounds)

__all__ = ["ABSORBER", "DIELECTRIC", "DIFFUSE", "EMITTER_KINDS", "GLOSSY", "MIRROR",
           "SCATTERING_MODELS", "TRANSLUCENT", "Emitter", "IesShaping", "LightGroup",
           "LuminaireInfo", "Material", "PartFrame", "Scene", "point_bounds"]
