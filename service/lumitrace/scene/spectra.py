"""The wavelength grid spectra live on, the CIE 1931 observer, and the few spectral sums the
tracer and the outputs share.

Spectra are sampled every nanometre from 380 to 780 nm (:data:`WAVELENGTHS`): emitters'
relative spectral power, materials' spectral reflectance and transmittance, a dielectric's
refractive index. A photon of a spectral scene carries a throughput per 10 nm band (see
:mod:`lumitrace.trace.kernels`), scaled so that it always carries the same luminous flux:
``Y`` stays the photon count the rest of the engine knows, and an escape's ``X`` and ``Z``
(:func:`band_weights` times its throughput) are tallied as exact integers in units of
1/:data:`FIXED_POINT`. colour-science supplies the observer and is imported only when a
scene has colour.
"""
from __future__ import annotations

import functools

import numpy as np

#: The spectral grid (nm): 380 to 780 in 1 nm steps.
WAVELENGTHS = np.arange(380, 781, dtype=np.float64)
#: X and Z tallies hold a photon's X and Z in units of 2**-20 of its Y (exact integer sums).
FIXED_POINT = 1 << 20
#: Photons carry their throughput in 10 nm bands (centres 380, 390, ..., 780 nm): band of
#: every grid wavelength, and the number of bands.
BAND_OF = ((WAVELENGTHS.astype(np.int64) - 375) // 10).clip(0, 40)
BANDS = 41
#: Wavelengths (nm) of the Fraunhofer d, F and C lines, which define an Abbe number.
LINE_D, LINE_F, LINE_C = 587.56, 486.13, 656.27


def colour_science():
    """colour-science, imported without its note that SciPy is absent: lumitrace uses none
    of its SciPy-based functions, and SciPy is not one of its dependencies."""
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message='"SciPy" related API features')
        import colour
    return colour


@functools.lru_cache(maxsize=1)
def observer() -> np.ndarray:
    """CIE 1931 2 degree colour-matching functions on :data:`WAVELENGTHS`, (401, 3)."""
    colour = colour_science()

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy()
    return np.ascontiguousarray(cmfs.align(_shape()).values, np.float64)


def _shape():
    colour = colour_science()

    return colour.SpectralShape(float(WAVELENGTHS[0]), float(WAVELENGTHS[-1]), 1.0)


@functools.lru_cache(maxsize=1)
def d65() -> np.ndarray:
    """CIE standard illuminant D65 on the grid (relative power): the white of a light whose
    colour is given in linear Rec.709 RGB only."""
    colour = colour_science()

    return np.ascontiguousarray(colour.SDS_ILLUMINANTS["D65"].copy().align(_shape()).values)


def photopic(wavelengths) -> np.ndarray:
    """V(lambda) (= ybar) at any wavelengths (nm), 0 outside the grid."""
    return np.interp(np.asarray(wavelengths, np.float64), WAVELENGTHS, observer()[:, 1],
                     left=0.0, right=0.0)


def grid_indices(wavelengths) -> tuple[np.ndarray, np.ndarray]:
    """The grid sample (nearest nanometre) of each wavelength (nm) and whether it is on the
    grid at all (380-780 nm)."""
    nm = np.rint(np.asarray(wavelengths, np.float64)).astype(np.int64) - int(WAVELENGTHS[0])
    inside = (nm >= 0) & (nm < WAVELENGTHS.size)
    return np.where(inside, nm, 0), inside


def tristimulus(spd) -> np.ndarray:
    """CIE XYZ (3,) of a spectrum on the grid, as the 1 nm sum the tracer estimates."""
    return np.asarray(spd, np.float64) @ observer()


def is_flat(values) -> bool:
    """Whether a spectrum on the grid is one value at every wavelength (to 1e-9)."""
    v = np.asarray(values, np.float64)
    return bool(v.size == 0 or np.ptp(v) <= 1e-9 * max(1.0, float(np.abs(v).max())))


def band_means(values) -> np.ndarray:
    """A spectrum on the grid averaged over each tracing band, (:data:`BANDS`,)."""
    v = np.asarray(values, np.float64)
    return np.bincount(BAND_OF, weights=v, minlength=BANDS) / np.bincount(BAND_OF, minlength=BANDS)


def band_weights(spd) -> np.ndarray:
    """The X, Y, Z a photon of spectrum ``spd`` carries in each tracing band per unit of
    its Y, (3, :data:`BANDS`): the 1 nm sums of power times the observer over the band,
    over the whole Y. A photon of unit throughput has Y 1 and its light's X/Y and Z/Y."""
    p = np.asarray(spd, np.float64)[:, None] * observer()
    total = float(p[:, 1].sum())
    if not total > 0.0:
        raise ValueError("the spectrum has no power where the eye sees (380-780 nm)")
    return np.stack([np.bincount(BAND_OF, weights=p[:, k], minlength=BANDS)
                     for k in range(3)]) / total


def chromaticity_ratios(spd) -> tuple[float, float]:
    """(X/Y, Z/Y) of a spectrum: what a photon of it adds to X and Z per unit of Y when no
    surface changes its colour."""
    xyz = tristimulus(spd)
    return float(xyz[0] / xyz[1]), float(xyz[2] / xyz[1])


def cauchy_ior(ior_d: float, abbe: float) -> np.ndarray:
    """Refractive index on the grid of a glass with index ``ior_d`` at the d line and Abbe
    number ``abbe`` = (n_d - 1) / (n_F - n_C), by Cauchy's n = A + B / lambda^2."""
    b = (ior_d - 1.0) / abbe / (LINE_F ** -2 - LINE_C ** -2)
    a = ior_d - b * LINE_D ** -2
    return a + b * WAVELENGTHS ** -2


def sellmeier_ior(coefficients) -> np.ndarray:
    """Refractive index on the grid from Sellmeier's equation, n^2 = 1 + sum B_k l^2 /
    (l^2 - C_k), ``coefficients`` (B1, B2, B3, C1, C2, C3) with C in square micrometres."""
    b, c = np.asarray(coefficients[:3], np.float64), np.asarray(coefficients[3:], np.float64)
    l2 = (WAVELENGTHS * 1e-3)[:, None] ** 2
    return np.sqrt(1.0 + (b * l2 / (l2 - c)).sum(axis=1))


def resample(wavelengths, values, hold: bool = False) -> np.ndarray:
    """A spectrum given at ``wavelengths`` (nm, increasing) on the grid: linear between the
    samples; outside them zero (a light's power) or, with ``hold``, the end values (a
    surface's reflectance)."""
    v = np.asarray(values, np.float64)
    return np.interp(WAVELENGTHS, np.asarray(wavelengths, np.float64), v,
                     left=v[0] if hold else 0.0, right=v[-1] if hold else 0.0)
