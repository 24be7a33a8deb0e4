"""The GLDF container (Global Lighting Data Format, ISO 7127) of a result: ``NAME.gldf``.

A zip holding ``product.xml`` (GLDF 1.0.0-rc.3) and the files it references: the EULUMDAT
and IES files (``ldc/``), the luminaire's geometry as L3D (``geo/``, see :mod:`.l3d`), the
datasheet (``doc/``) and the photometric solid (``image/``) where written. ``product.xml``
describes one fixed light source, one emitter with the EULUMDAT photometry and the
descriptive figures of the result record, and one product with one variant whose geometry
is the L3D model, its emitter at the model's light emitting object.

The luminaire's own data (:class:`~lumitrace.scene.LuminaireInfo`, from the luminaire
prim's ``lumitrace:*`` attributes) fills the fields GLDF has for it: manufacturer
(``Header/Manufacturer``, ``FixedLightSource/Manufacturer``), luminaire name
(``ProductMetaData/Name``, ``Variant/Name``, L3D ``Header/Name``), catalogue number
(``ProductMetaData/ProductNumber``, ``Variant/ProductNumber``, ``UniqueProductId``), lamp
description (``FixedLightSource/Name``), input power (``RatedInputPower``, and the
efficacy) and colour rendering index (``ColorInformation/ColorRenderingIndex``).
"""
from __future__ import annotations

import io
import math
import uuid
import zipfile
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Mapping

from .. import __version__
from .l3d import EMITTER_PART
from .xml_text import xml_text

#: GLDF format version written (``Header/FormatVersion``): 1.0.0-rc.3.
FORMAT_VERSION = (1, 0, 3)


@dataclass(frozen=True)
class GldfFiles:
    """The files a container holds (name in the container -> bytes): ``ldt`` and ``ies``
    (photometry), ``l3d`` (geometry), ``pdf`` (the datasheet, or None), ``png`` (a
    picture, or None)."""

    ldt: tuple[str, bytes]
    ies: tuple[str, bytes]
    l3d: tuple[str, bytes]
    pdf: tuple[str, bytes] | None = None
    png: tuple[str, bytes] | None = None


#: Folder in the container and GLDF ``contentType`` per kind of file.
_KINDS = {"ldt": ("ldc", "ldc/eulumdat"), "ies": ("ldc", "ldc/ies"),
          "l3d": ("geo", "geo/l3d"), "pdf": ("doc", "document/pdf"),
          "png": ("image", "image/png")}


def _locale(tag: str, text: str) -> str:
    return f'<{tag}><Locale language="en">{xml_text(text)}</Locale></{tag}>'


def _num(value: float) -> str:
    """A double as XML text that reads back to the same double."""
    return repr(float(value))


def _in_range(value: float | None, lo: float, hi: float) -> float | None:
    """``value`` where it is a finite number in [lo, hi], else None (the stage reader
    refuses others; a scene made in code may hold anything)."""
    if value is None or not math.isfinite(value) or not lo <= value <= hi:
        return None
    return float(value)


def descriptive_photometry(record: Mapping, input_power_w: float | None) -> str:
    """``DescriptivePhotometry`` from the record: LOR, efficacy (lm/W, with a power),
    downward flux fraction, divergences (beam and field angles), the CIE flux code, the
    catalogue UGR and the BUG rating where the record has them."""
    def fraction(key):
        v = record.get(key)
        return None if v is None else min(max(float(v), 0.0), 1.0)

    parts = []
    lor, dff = fraction("light_output_ratio"), fraction("downward_flux_fraction")
    if lor is not None:
        parts.append(f"<LightOutputRatio>{_num(lor)}</LightOutputRatio>")
    flux = record.get("luminous_flux")
    if input_power_w and flux is not None:
        parts.append(f"<LuminousEfficacy>{_num(min(flux / input_power_w, 683.0))}"
                     "</LuminousEfficacy>")
    if dff is not None:
        parts.append(f"<DownwardFluxFraction>{_num(dff)}</DownwardFluxFraction>")
        if lor is not None:
            parts.append(f"<DownwardLightOutputRatio>{_num(lor * dff)}"
                         "</DownwardLightOutputRatio>"
                         f"<UpwardLightOutputRatio>{_num(lor * (1.0 - dff))}"
                         "</UpwardLightOutputRatio>")
    for tag, what in (("TenthPeakDivergence", "field"), ("HalfPeakDivergence", "beam")):
        a, b = record.get(f"{what}_angle_c0_c180"), record.get(f"{what}_angle_c90_c270")
        if a is not None and b is not None:
            parts.append(f"<{tag}><C0-C180>{_num(a)}</C0-C180><C90-C270>{_num(b)}"
                         f"</C90-C270></{tag}>")
    if record.get("cie_flux_code"):
        parts.append(f"<CIE-FluxCode>{xml_text(record['cie_flux_code'])}</CIE-FluxCode>")
    ugr = catalogue_ugr(record)
    if ugr is not None:  # X crosswise, Y endwise
        parts.append(f"<UGR-4H8H-70-50-20-LQ><X>{_num(ugr[0])}</X><Y>{_num(ugr[1])}</Y>"
                     "</UGR-4H8H-70-50-20-LQ>")
    if record.get("bug_rating"):
        parts.append(f"<LightDistributionBUG-Rating>{xml_text(record['bug_rating'])}"
                     "</LightDistributionBUG-Rating>")
    return f"<DescriptivePhotometry>{''.join(parts)}</DescriptivePhotometry>" if parts else ""


def catalogue_ugr(record: Mapping) -> tuple[float, float] | None:
    """The catalogue UGR (4H 8H, reflectances 70/50/20) crosswise and endwise, where the
    record has it (the glare figures are optional: None without them)."""
    cross = record.get("ugr_4h8h_70_50_20")
    end = record.get("ugr_4h8h_70_50_20_endwise")
    if cross is None or end is None:
        return None
    return float(cross), float(end)


def product_xml(record: Mapping, info, files: GldfFiles, name: str,
                when: datetime | None = None, gldf_id: str | None = None) -> str:
    """``product.xml`` of a result (``record``: the result record; ``info``: the
    luminaire's :class:`~lumitrace.scene.LuminaireInfo`; ``name``: the luminaire's name
    as the files give it)."""
    when = (when or datetime.now(timezone.utc)).replace(microsecond=0)
    stamp = when.strftime("%Y-%m-%dT%H:%M:%SZ")
    major, minor, pre = FORMAT_VERSION
    manufacturer = info.manufacturer or "unknown manufacturer"
    power = _in_range(info.input_power_w, 0.0, math.inf)
    number = info.catalogue_number or name
    present = {k: getattr(files, k) for k in _KINDS if getattr(files, k) is not None}
    file_list = "".join(f'<File id="file_{k}" contentType="{_KINDS[k][1]}" '
                        f'type="localFileName">{xml_text(v[0])}</File>'
                        for k, v in present.items())
    photometries = ("<Photometries><Photometry id=\"photometry_ldt\">"
                    "<PhotometryFileReference fileId=\"file_ldt\"/>"
                    f"{descriptive_photometry(record, power)}</Photometry>"
                    "<Photometry id=\"photometry_ies\"><PhotometryFileReference "
                    "fileId=\"file_ies\"/></Photometry></Photometries>")
    colour = ""
    ra = _in_range(info.colour_rendering_index, 0.0, 100.0)  # what GLDF's int can hold
    if ra is not None or record.get("cct_K") is not None:
        cri = "" if ra is None else \
            f"<ColorRenderingIndex>{int(round(ra))}</ColorRenderingIndex>"
        cct = "" if record.get("cct_K") is None else \
            f"<CorrelatedColorTemperature>{int(round(record['cct_K']))}" \
            "</CorrelatedColorTemperature>"
        colour = f"<ColorInformation>{cri}{cct}</ColorInformation>"
    lamp = info.lamp or f"lumitrace emitters, {_num(record.get('lamp_flux') or 0.0)} lm"
    light_source = ("<LightSources><FixedLightSource id=\"light_source\">"
                    f"{_locale('Name', lamp)}"
                    f"<Manufacturer>{xml_text(manufacturer)}</Manufacturer>"
                    f"<RatedInputPower>{_num(power or 0.0)}</RatedInputPower>"
                    f"{colour}</FixedLightSource></LightSources>")
    flux = record.get("luminous_flux") or 0.0
    emitter = ("<Emitters><Emitter id=\"emitter\"><FixedLightEmitter>"
               f"{_locale('Name', 'luminous opening')}"
               "<PhotometryReference photometryId=\"photometry_ldt\"/>"
               "<LightSourceReference fixedLightSourceId=\"light_source\"/>"
               f"<RatedLuminousFlux>{int(round(flux))}</RatedLuminousFlux>"
               "</FixedLightEmitter></Emitter></Emitters>")
    geometry = ("<Geometries><ModelGeometry id=\"model\"><GeometryFileReference "
                "fileId=\"file_l3d\" levelOfDetail=\"High\"/></ModelGeometry></Geometries>")
    general = (f"<GeneralDefinitions><Files>{file_list}</Files>{photometries}{light_source}"
               f"{emitter}{geometry}</GeneralDefinitions>")
    description = (f"computed by photon tracing of the USD stage {record.get('stage') or ''}"
                   f" with lumitrace {__version__}: {record.get('photons') or 0} photons, "
                   f"seed {record.get('seed')}, input hash {record.get('input_hash') or ''}")
    pictures = "" if files.png is None else \
        '<Pictures><Image fileId="file_png" imageType="Product Picture"/></Pictures>'
    variant = ("<Variants><Variant id=\"variant\">"
               f"{_locale('ProductNumber', number)}{_locale('Name', name)}"
               f"{_locale('Description', description)}"
               "<Geometry><ModelGeometryReference geometryId=\"model\">"
               "<EmitterReference emitterId=\"emitter\">"
               f"<EmitterObjectExternalName>{EMITTER_PART}</EmitterObjectExternalName>"
               "</EmitterReference></ModelGeometryReference></Geometry>"
               "</Variant></Variants>")
    meta = (f"<ProductMetaData><UniqueProductId>{xml_text(number)}</UniqueProductId>"
            f"{_locale('ProductNumber', number)}{_locale('Name', name)}"
            f"{_locale('Description', description)}{pictures}</ProductMetaData>")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<Root xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
            'xsi:noNamespaceSchemaLocation="https://gldf.io/xsd/gldf/1.0.0-rc.3/gldf.xsd">'
            f"<Header><Manufacturer>{xml_text(manufacturer)}</Manufacturer>"
            f'<FormatVersion major="{major}" minor="{minor}" pre-release="{pre}"/>'
            f"<CreatedWithApplication>lumitrace {__version__}</CreatedWithApplication>"
            f"<GldfCreationTimeCode>{stamp}</GldfCreationTimeCode>"
            f"<UniqueGldfId>{gldf_id or uuid.uuid4()}</UniqueGldfId></Header>"
            f"{general}<ProductDefinitions>{meta}{variant}</ProductDefinitions></Root>\n")


def gldf_bytes(record: Mapping, info, files: GldfFiles, name: str,
               when: datetime | None = None, gldf_id: str | None = None) -> bytes:
    """The GLDF container (zip bytes): ``product.xml`` and every file it references, each
    in its folder."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("product.xml", product_xml(record, info, files, name, when, gldf_id))
        for kind, (folder, _) in _KINDS.items():
            item = getattr(files, kind)
            if item is not None:
                z.writestr(f"{folder}/{item[0]}", item[1])
    return buf.getvalue()
