"""The colour of lights and surfaces, read from the stage as spectra on the scene's grid.

A light's spectrum comes from, first match: ``lumitrace:spectrum`` (sampled relative
power), ``lumitrace:illuminant`` (a Planckian or CIE daylight colour temperature, or a
colour-science illuminant or light source by name), UsdLux's colour temperature (a
Planckian radiator, tinted by a coloured ``inputs:color``), a coloured ``inputs:color``
alone (D65 tinted by it, linear Rec.709 as UsdLux colours are). A light with none of them
has no colour. A surface's spectral albedo comes from the ``lumitrace:*Spectrum``
attributes, else from a coloured UsdPreviewSurface colour: a smooth reflectance recovered
from the colour (Mallett and Yuksel 2019), scaled to the albedo the material already has; a
dielectric disperses by its Abbe number (Cauchy) or its Sellmeier coefficients.
colour-science is imported only when a stage has a colour.
"""
from __future__ import annotations

import numpy as np
from pxr import Usd, UsdLux

from .. import schema
from ..errors import StageError
from ..scene import spectra
from .validate import check_array, check_finite

#: Where the light or surface spectrum attributes live, and their allowed values.
SPECTRUM_RANGES = {schema.SPECTRUM: (0.0, np.inf), schema.REFLECTANCE_SPECTRUM: (0.0, 1.0),
                   schema.SPECULAR_SPECTRUM: (0.0, 1.0),
                   schema.TRANSMITTANCE_SPECTRUM: (0.0, 1.0)}


def sampled_spectrum(prim: Usd.Prim, name: str, time: Usd.TimeCode) -> np.ndarray | None:
    """An authored (wavelength nm, value) pairs attribute on the grid, checked; None when
    not authored."""
    attr = prim.GetAttribute(name)
    if not attr or not attr.HasAuthoredValue():
        return None
    where = str(prim.GetPath())
    pairs = check_array(attr.Get(time), where, name, width=2)
    if len(pairs) < 2:
        raise StageError(f"needs at least two (wavelength, value) pairs, got {len(pairs)}",
                         where, name)
    if not np.isfinite(pairs).all():
        raise StageError("holds NaN or infinite values", where, name)
    wl, v = pairs[:, 0], pairs[:, 1]
    if (np.diff(wl) <= 0).any():
        raise StageError("wavelengths must increase", where, name)
    low, high = SPECTRUM_RANGES[name]
    if (v < low).any() or (v > high).any():
        bad = v[(v < low) | (v > high)][0]
        allowed = f">= {low:g}" if np.isinf(high) else f"in [{low:g}, {high:g}]"
        raise StageError(f"values must be {allowed}, got {bad:g}", where, name)
    hold = name != schema.SPECTRUM  # a surface keeps its end values, a light has no power
    out = spectra.resample(wl, v, hold=hold)
    if not hold and not (out @ spectra.observer()[:, 1]) > 0.0:
        raise StageError(f"has no power between {spectra.WAVELENGTHS[0]:g} and "
                         f"{spectra.WAVELENGTHS[-1]:g} nm, where the eye sees", where, name)
    return out


def named_illuminant(text: str, where: str) -> np.ndarray:
    """The spectrum of ``lumitrace:illuminant``: "blackbody T", "daylight T" (K) or a
    colour-science illuminant or light source name."""
    colour = spectra.colour_science()

    words = text.split()
    if len(words) == 2 and words[0].lower() in ("blackbody", "daylight"):
        try:
            cct = float(words[1])
        except ValueError:
            cct = float("nan")
        lo, hi = (1000.0, 25000.0) if words[0].lower() == "blackbody" else (4000.0, 25000.0)
        if not lo <= cct <= hi:
            raise StageError(f"{words[0]} needs a colour temperature in [{lo:g}, {hi:g}] K, "
                             f"got {words[1]!r}", where, schema.ILLUMINANT)
        return blackbody(cct) if words[0].lower() == "blackbody" else daylight(cct)
    for table in (colour.SDS_ILLUMINANTS, colour.SDS_LIGHT_SOURCES):
        if text in table:
            return _on_grid(table[text])
    raise StageError(f"unknown illuminant {text!r}: give 'blackbody K', 'daylight K' or a "
                     "colour-science illuminant or light source name (D65, A, FL2, ...)",
                     where, schema.ILLUMINANT)


def _on_grid(sd) -> np.ndarray:
    return np.ascontiguousarray(sd.copy().align(spectra._shape()).values, np.float64)


def blackbody(cct: float) -> np.ndarray:
    """A Planckian radiator of ``cct`` K on the grid (relative power)."""
    colour = spectra.colour_science()

    return _on_grid(colour.sd_blackbody(cct, spectra._shape()))


def daylight(cct: float) -> np.ndarray:
    """CIE daylight of correlated colour temperature ``cct`` K on the grid."""
    colour = spectra.colour_science()

    xy = colour.temperature.CCT_to_xy_CIE_D(cct)
    return _on_grid(colour.sd_CIE_illuminant_D_series(xy))


def tint(rgb) -> np.ndarray | None:
    """The smooth reflectance (grid, in [0, 1]) of a linear Rec.709 colour, normalised to
    its largest component; None for a grey (no colour)."""
    c = np.clip(np.asarray(rgb, np.float64), 0.0, None)
    if c.max() <= 0.0 or np.ptp(c) <= 1e-6 * c.max():
        return None
    colour = spectra.colour_science()

    sd = colour.recovery.RGB_to_sd_Mallett2019(c / c.max())
    return np.clip(_on_grid(sd), 0.0, 1.0)


def light_spectrum(prim: Usd.Prim, light: UsdLux.LightAPI, time: Usd.TimeCode) -> tuple:
    """A light's relative spectral power on the grid, () when the stage gives it no
    colour (see the module's order)."""
    where = str(prim.GetPath())
    sampled = sampled_spectrum(prim, schema.SPECTRUM, time)
    if sampled is not None:
        return tuple(sampled)
    attr = prim.GetAttribute(schema.ILLUMINANT)
    if attr and attr.HasAuthoredValue() and str(attr.Get(time) or "").strip():
        return tuple(named_illuminant(str(attr.Get(time)).strip(), where))
    color = light.GetColorAttr().Get(time)
    shape = tint(color) if color is not None else None
    if light.GetEnableColorTemperatureAttr().Get(time):
        cct = check_finite(light.GetColorTemperatureAttr().Get(time), where,
                           "inputs:colorTemperature")
        if not 1000.0 <= cct <= 25000.0:
            raise StageError(f"must be in [1000, 25000] K, got {cct:g}", where,
                             "inputs:colorTemperature")
        base = blackbody(cct)
    elif shape is not None:
        base = spectra.d65()
    else:
        return ()
    return tuple(base * shape if shape is not None else base)


def ray_file_colour(f, path: str) -> tuple[tuple, float | None]:
    """The spectrum of a TM-25 file ``f`` (read from ``path``) whose rays carry wavelengths
    (their radiant flux per nanometre) and its luminous flux (683 lm/W V(lambda) times its
    rays' radiant flux); ((), None) for a file without wavelengths."""
    if f.wavelengths is None:
        return (), None
    radiant = f.radiant.astype(np.float64)
    nm, inside = spectra.grid_indices(f.wavelengths)
    spd = np.bincount(nm[inside], weights=radiant[inside], minlength=spectra.WAVELENGTHS.size)
    if not (spd @ spectra.observer()[:, 1]) > 0.0:
        raise StageError("its rays have no power where the eye sees (380-780 nm)", path)
    return tuple(spd / spd.max()), float(683.0 * (spectra.photopic(f.wavelengths)
                                                  * radiant).sum())


def surface_spectra(prims: list[Usd.Prim], time: Usd.TimeCode, scattering: str,
                    albedos: dict[str, float], colour=None) -> dict:
    """The :class:`~lumitrace.scene.Material` spectral fields of a surface: authored
    ``lumitrace:*Spectrum`` attributes (the first of ``prims`` that has one: the gprim,
    then its material), else the albedo of the scattering model given a spectral shape by
    the UsdPreviewSurface ``colour`` (linear Rec.709); ``albedos`` are the scalar ones
    (reflectance, specular, transmittance). Neutral surfaces get nothing."""
    out: dict = {}
    for name, field, scalar in (
            (schema.REFLECTANCE_SPECTRUM, "reflectance_spectrum", "reflectance"),
            (schema.SPECULAR_SPECTRUM, "specular_spectrum", "specular_reflectance"),
            (schema.TRANSMITTANCE_SPECTRUM, "transmittance_spectrum", "transmittance")):
        for prim in prims:
            values = sampled_spectrum(prim, name, time)
            if values is not None:  # a flat one is its scalar; the scalar follows it
                out[field] = () if spectra.is_flat(values) else tuple(values)
                out[scalar] = float(values[0] if spectra.is_flat(values)
                                    else values @ _d65_luminous())
                break
    for prim in prims:
        attr = prim.GetAttribute(schema.ABBE_NUMBER)
        if attr and attr.HasAuthoredValue():
            abbe = check_finite(attr.Get(time), str(prim.GetPath()), schema.ABBE_NUMBER)
            if abbe < 0.0 or 0.0 < abbe < 1.0:
                raise StageError(f"must be 0 (no dispersion) or >= 1, got {abbe:g}",
                                 str(prim.GetPath()), schema.ABBE_NUMBER)
            if abbe and scattering == "dielectric":
                out["abbe_number"] = float(abbe)
            break
    for prim in prims:
        attr = prim.GetAttribute(schema.SELLMEIER)
        if attr and attr.HasAuthoredValue():
            coefficients = _sellmeier(attr.Get(time), str(prim.GetPath()))
            if scattering == "dielectric":
                out["sellmeier"] = coefficients
            break
    field = {"diffuse": "reflectance_spectrum", "translucent": "reflectance_spectrum",
             "mirror": "specular_spectrum", "glossy": "specular_spectrum"}.get(scattering)
    shape = tint(colour) if colour is not None and field is not None else None
    if shape is not None and field not in out:
        albedo = albedos[field.split("_")[0]]
        y = float(shape @ _d65_luminous())
        if y > 0.0:
            out[field] = tuple(np.clip(shape * (albedo / y), 0.0, 1.0))
    return out


def _sellmeier(value, where: str) -> tuple:
    """Checked Sellmeier coefficients (B1, B2, B3, C1, C2, C3; C in um^2): six finite
    numbers, C >= 0, giving an index >= 1 at every wavelength of the grid."""
    v = check_array(value, where, schema.SELLMEIER)
    if v.size != 6 or not np.isfinite(v).all():
        raise StageError(f"needs six finite numbers (B1, B2, B3, C1, C2, C3), got {v.size}",
                         where, schema.SELLMEIER)
    if (v[3:] < 0).any():
        raise StageError("C1, C2, C3 (square micrometres) must be >= 0", where,
                         schema.SELLMEIER)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = spectra.sellmeier_ior(v)
    if not (np.isfinite(n).all() and (n >= 1.0).all()):
        raise StageError("gives no refractive index >= 1 somewhere in 380-780 nm (a "
                         "resonance C inside the visible?)", where, schema.SELLMEIER)
    return tuple(float(x) for x in v)


def _d65_luminous() -> np.ndarray:
    """Weights (grid) of a reflectance's luminous average under D65."""
    w = spectra.d65() * spectra.observer()[:, 1]
    return w / w.sum()
