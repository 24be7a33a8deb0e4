"""Photon scattering at surfaces, vectorised per scattering model.

Scattering is analog: a photon keeps its flux and survives with the probability of the
material's albedo (Russian roulette with the albedo as survival probability, which is
unbiased and keeps every photon of an emitter at the same weight). Surfaces are two-sided
except for dielectrics, whose front side (counter-clockwise winding) faces the air.

Each photon carries a linear polarisation direction (unit vector across its direction).
Light from the sources and from diffuse surfaces is unpolarised (a random direction per
photon); dielectric and specular surfaces reflect and transmit the s and p components with
their own Fresnel amplitudes. Without it a clear slab would transmit too little at oblique
angles: (1 - F)/(1 + F) of the mean F instead of the mean of (1 - R_s)/(1 + R_s) and
(1 - R_p)/(1 + R_p), several percent at 60 degrees.

The models themselves are compiled (:func:`lumitrace.trace.kernels.scatter_one`); this
module holds the material table they read and a vectorised entry point.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import Material
from . import compiled

#: Marks an unpolarised photon in a polarisation array (NaN in the first component).
UNPOLARISED = np.nan


@dataclass(frozen=True)
class MaterialTable:
    """Per-material parameters as arrays indexed by material number (M,), and for a
    spectral scene the same per tracing band, (M, bands) each (``spectra``: reflectance,
    specular, transmittance, ior; None when no surface has a colour)."""

    kind: np.ndarray
    reflectance: np.ndarray
    specular: np.ndarray
    transmittance: np.ndarray
    ior: np.ndarray
    alpha: np.ndarray
    spectra: tuple | None = None

    #: The spectral properties, in the order of :attr:`spectra`.
    SPECTRAL = ("reflectance", "specular", "transmittance", "ior")

    @classmethod
    def from_materials(cls, materials: tuple[Material, ...],
                       spectral: bool = False) -> "MaterialTable":
        f = lambda name: np.array([getattr(m, name) for m in materials], dtype=np.float64)  # noqa: E731
        spectra = None
        if spectral:
            from ..scene.spectra import BANDS, band_means

            spectra = tuple(np.ascontiguousarray(
                np.stack([band_means(m.spectrum(name)) for m in materials])
                if materials else np.zeros((0, BANDS))) for name in cls.SPECTRAL)
        return cls(kind=np.array([m.kind for m in materials], dtype=np.int8),
                   reflectance=f("reflectance"), specular=f("specular_reflectance"),
                   transmittance=f("transmittance"), ior=f("ior"),
                   alpha=np.maximum(f("roughness") ** 2, 1e-4), spectra=spectra)


def scatter(table: MaterialTable, mat: np.ndarray, d: np.ndarray, ng: np.ndarray,
            u: list[np.ndarray], pol: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """New directions (3, N), survival flags (N,) and polarisations (3, N) of photons
    arriving along ``d`` (3, N) with polarisation ``pol`` at surfaces with unit geometric
    normals ``ng`` and material numbers ``mat``; ``u`` holds four uniform arrays.

    The tracer's own per-photon code, run over arrays (for tests and tools). ``pol`` None
    means a scene without dielectrics: nothing is spent on polarisation (None returned).
    """
    n = d.shape[1]
    polarised = pol is not None
    out, pol_out = np.empty((3, n)), np.empty((3, n))
    alive = np.empty(n, dtype=bool)
    f64 = lambda a: np.ascontiguousarray(a, np.float64)  # noqa: E731
    compiled.scatter_many(np.asarray(table.kind, np.int64), f64(table.reflectance),
                         f64(table.specular), f64(table.transmittance), f64(table.ior),
                         f64(table.alpha), np.asarray(mat, np.int64), f64(d), f64(ng),
                         *(f64(x) for x in u), f64(pol) if polarised else np.zeros((3, n)),
                         polarised, out, pol_out, alive)
    return out, alive, (pol_out if polarised else None)
