"""Any text and any number a user gives as the luminaire's own data: either one clear refusal
where it enters (the stage reader and a scene delta agree, naming the prim, the property and
the character), or files that third-party readers accept with the text intact as far as
their format holds it: the LDT read by ``pyldt``, the IES by ``eulumdat-ies``, the GLDF's
``product.xml`` and the L3D's ``structure.xml`` validated by ``xmlschema`` against their
schemas and read by ``gldf-rs-python`` and ``l3d-rs-python``. Property-based (hypothesis),
with few examples: the suite stays fast."""
from __future__ import annotations

import dataclasses
import io
import json
import math
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers.paths import ROOT
from helpers.traced import traced
from hypothesis import HealthCheck, event, given, settings, strategies as st
from pxr import Sdf, Usd

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)
from lumitrace.delta.apply import apply_deltas
from lumitrace.delta.protocol import DeltaError
from lumitrace.errors import StageError
from lumitrace.photometry.eulumdat import read_ldt
from lumitrace.photometry.lm63 import read_ies
from lumitrace.photometry.plain_text import one_line
from lumitrace.publish.datasheet_content import luminaire_name
from lumitrace.publish.gldf import GldfFiles, gldf_bytes
from lumitrace.publish.l3d import l3d_bytes
from lumitrace.publish.outputs import build_record
from lumitrace.publish.photometric import photometric_paths, write_photometric_files
from lumitrace.schema import (AUTHOR, CATALOGUE_NUMBER, COLOUR_RENDERING_INDEX, INPUT_POWER,
                              LAMP_DESCRIPTION, LUMINAIRE_NAME, LUMINAIRE_TEXT, MANUFACTURER)
from lumitrace.stage.luminaire_data import refused_character
from lumitrace.stage.reader import scene_from_stage

pyldt = pytest.importorskip("pyldt")
eulumdat_ies = pytest.importorskip("eulumdat_ies")
gldf_rs = pytest.importorskip("gldf_rs_python")
l3d_rs = pytest.importorskip("l3d")
xmlschema = pytest.importorskip("xmlschema")

REFERENCE = ROOT.parent / "shared" / "reference"
GLDF_XSD, L3D_XSD = REFERENCE / "gldf" / "gldf.xsd", REFERENCE / "l3d" / "l3d.xsd"
#: Where each text attribute is in the LDT (pyldt's header field, the field's length).
LDT_FIELDS = {MANUFACTURER: ("company", 78), LUMINAIRE_NAME: ("luminaire_name", 78),
              CATALOGUE_NUMBER: ("luminaire_number", 78), LAMP_DESCRIPTION: ("lamp_types", 24)}
#: Where each text attribute is in the IES (its keyword, eulumdat-ies's header field).
IES_FIELDS = {MANUFACTURER: ("MANUFAC", "company"), LUMINAIRE_NAME: ("LUMINAIRE",
              "luminaire_name"), CATALOGUE_NUMBER: ("LUMCAT", "luminaire_number"),
              LAMP_DESCRIPTION: ("LAMP", None)}

#: Pieces of hostile text: line breaks, a terminal's colour code, XML's specials, IES
#: keywords, mathtext, characters outside Latin-1 and outside the BMP, and the ones no XML
#: file can hold.
PIECES = ["\n", "\r\n", "\t", "\x1b[31m", "\x00", "\x85", "\u2028", "\ufffe", "\ud800",
          "<", "&", "]]>", '"', "'", "[MORE]", "TILT=NONE", "$x^$", "M\u00fcnchen",
          "\u6771\u4eac", "\U0001f600", "\u00a0", "  ", "e\u0301", "\ufb01", ","]
#: Any text (every code point, surrogates included) with hostile pieces in it, or text of
#: every category but those refused, which must reach the files.
TEXT = st.one_of(
    st.lists(st.one_of(st.characters(codec=None, categories=None).map(str),
                       st.sampled_from(PIECES), st.text(min_size=20, max_size=120)),
             max_size=14).map("".join),
    st.lists(st.one_of(st.text(st.characters(exclude_categories=("Cc", "Cs", "Zl", "Zp")),
                               max_size=100),
                       st.sampled_from([p for p in PIECES if p.isprintable()])),
             max_size=8).map("".join),
    st.text(st.characters(exclude_categories=("Cc", "Cs", "Zl", "Zp")), min_size=990,
            max_size=1010))
NUMBER = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(
    [-0.0, 0.0, 100.0, 100.0000001, -1e-300, 5e-324, 1e308, 99.5, 13.5])
FEW = settings(max_examples=30, deadline=None, derandomize=True,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@pytest.fixture(scope="module")
def base():
    """The demo traced once (scene, photometry, record) and the two XML schemas."""
    if not (GLDF_XSD.is_file() and L3D_XSD.is_file()):
        pytest.skip("the GLDF and L3D schemas are not in ../shared/reference")
    scene, result, ph, _ = traced("demo", 20_000)
    record = build_record(result, ph, {})
    folder = Path(tempfile.mkdtemp(prefix="lumitrace-text-"))
    return (scene, ph, record, folder, xmlschema.XMLSchema(str(GLDF_XSD)),
            xmlschema.XMLSchema(str(L3D_XSD)))


#: A small luminaire: a sphere light on the default prim, which holds the luminaire API.
LUMINAIRE = """#usda 1.0
(
    defaultPrim = "Luminaire"
    metersPerUnit = 1
    upAxis = "Z"
)
def Xform "Luminaire" (prepend apiSchemas = ["LumitraceLuminaireAPI"])
{
    def SphereLight "Source" (prepend apiSchemas = ["LumitraceEmitterAPI"])
    {
        float inputs:radius = 0.001
        float lumitrace:luminousFlux = 1000
    }
}
"""


def _stage(name: str, value) -> Usd.Stage:
    """The small luminaire, its default prim holding ``name`` = ``value``."""
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.ImportFromString(LUMINAIRE)
    stage = Usd.Stage.Open(layer)
    stage.GetPrimAtPath("/Luminaire").GetAttribute(name).Set(value)
    return stage


def _entered(name: str, value):
    """What the two ways in make of ``value``: (the scene's luminaire data or the stage
    reader's error, the delta's problems or None where it was accepted)."""
    text = isinstance(value, str)
    representable = not text or ("\x00" not in value and not any(
        0xD800 <= ord(c) <= 0xDFFF for c in value))  # what a USD string can hold
    read = None
    if representable:
        try:
            read = scene_from_stage(_stage(name, value)).info
        except StageError as exc:
            read = exc
    stage = _stage(name, 1.0 if not text else "x")
    edits = Sdf.Layer.CreateAnonymous(".usda")
    stage.GetSessionLayer().subLayerPaths.append(edits.identifier)
    try:
        apply_deltas(stage, edits, [{"op": "set", "path": "/Luminaire", "property": name,
                                     "value": value}], ROOT)
        refused = None
    except DeltaError as exc:
        assert exc.status == 422
        refused = exc.problems
    return read, refused


def _first_refused(text: str) -> str | None:
    return next((c for c in text if refused_character(c)), None)


def _check_refusal(name: str, value, read, refused) -> None:
    """One clear refusal on both ways in, naming the prim, the property and, for text, the
    first character refused."""
    event("refused")
    assert refused is not None and len(refused) == 1, (value, refused)
    assert refused[0].where == f"/deltas/0 /Luminaire.{name}"
    messages = [refused[0].why] + ([str(read)] if read is not None else [])
    if read is not None:
        assert isinstance(read, StageError) and str(read).startswith(f"/Luminaire.{name}: ")
    bad = _first_refused(value) if isinstance(value, str) else None
    for message in messages:
        if bad is not None:
            assert f"U+{ord(bad):04X}" in message, message
        elif isinstance(value, str):
            assert "characters long" in message
        else:
            assert "finite" in message or "must be" in message


def _written(base, info):
    """The IES, LDT, GLDF and L3D written for ``info``: (paths, gldf bytes, l3d bytes)."""
    scene, ph, record, folder, _, _ = base
    scene = dataclasses.replace(scene, info=info)
    paths = photometric_paths(folder, "dl")
    write_photometric_files(scene, ph, paths, "dl", pictures=False, run_id="0123456789abcdef")
    name = luminaire_name(record, info)
    l3d = l3d_bytes(scene, ph.opening, name)
    files = GldfFiles(ldt=("dl.ldt", paths["ldt"].read_bytes()),
                      ies=("dl.ies", paths["ies"].read_bytes()), l3d=("dl.l3d", l3d))
    return paths, gldf_bytes(record, info, files, name), l3d, name


def _check_files(base, paths, gldf: bytes, l3d: bytes, name: str):
    """The third-party readers accept every file, its numbers those we wrote; returns what
    they read: (pyldt's header, eulumdat-ies's header, the IES keywords, the GLDF's JSON,
    the L3D's structure JSON)."""
    _, ph, _, _, gldf_schema, l3d_schema = base
    event("written")
    ldt = pyldt.LdtReader.read(str(paths["ldt"]))
    ours = read_ldt(paths["ldt"])
    assert ldt.header.mc == ours.mc and ldt.header.ng == ours.ng
    assert np.asarray(ldt.intensities[0], float) == pytest.approx(ours.cd_per_klm[0], abs=1e-3)
    from_ies = eulumdat_ies.ies_to_ldt(str(paths["ies"]))
    assert from_ies.header.ng == len(ph.grid.gamma)
    ies = read_ies(paths["ies"])
    assert ies.candela == pytest.approx(ph.grid.candela, rel=1e-5, abs=1e-9)
    assert all(len(line) <= 256 and line.isascii()
               for line in paths["ies"].read_text("ascii").splitlines())
    product = zipfile.ZipFile(io.BytesIO(gldf)).read("product.xml").decode("utf-8")
    assert [f"{e.path}: {e.reason}" for e in gldf_schema.iter_errors(product)] == []
    doc = json.loads(gldf_rs.json_from_xml_str(product))
    structure = zipfile.ZipFile(io.BytesIO(l3d)).read("structure.xml").decode("utf-8")
    assert [f"{e.path}: {e.reason}" for e in l3d_schema.iter_errors(structure)] == []
    json.loads(l3d_rs.parse_l3d(l3d))
    return ldt.header, from_ies.header, ies.keywords, doc, json.loads(
        l3d_rs.parse_structure_xml(structure))


@FEW
@given(name=st.sampled_from(LUMINAIRE_TEXT), text=TEXT)
def test_any_text_is_refused_by_name_or_written_intact(base, name, text):
    read, refused = _entered(name, text)
    if refused is not None or isinstance(read, StageError) or read is None:
        _check_refusal(name, text, read, refused)
        return
    info = read
    value = {MANUFACTURER: info.manufacturer, LUMINAIRE_NAME: info.name,
             CATALOGUE_NUMBER: info.catalogue_number, LAMP_DESCRIPTION: info.lamp,
             AUTHOR: info.author}[name]
    assert value == text.strip()
    paths, gldf, l3d, shown = _written(base, info)
    ldt, from_ies, keywords, doc, structure = _check_files(base, paths, gldf, l3d, shown)
    if name == AUTHOR:  # the GLDF's alone; left out where not given (gldf-rs then
        # fills in its placeholder)
        assert doc["Header"].get("Author") == (value or "__empty__")
        assert (b"<Author>" in zipfile.ZipFile(io.BytesIO(gldf)).read("product.xml")) \
            == bool(value)
        return
    if not value:  # not given: the files' defaults
        return
    # EULUMDAT: the field as one Latin-1 line cut at its length; exact where it fits
    field, width = LDT_FIELDS[name]
    got = getattr(ldt, field)
    got = got[0] if isinstance(got, list) else got
    assert got == one_line(value, "latin-1", width)
    if len(value) <= width and " ".join(value.split()) == value and value.isprintable():
        try:
            value.encode("latin-1")
            assert got == value
        except UnicodeEncodeError:
            pass
    # IES: ASCII, continued on [MORE] lines, which our reader joins (eulumdat-ies keeps the
    # first line); exact where the value is printable ASCII of one line
    key, ies_field = IES_FIELDS[name]
    if one_line(value):
        joined = " ".join(keywords[key].split())
        assert joined == one_line(value) or len(one_line(value)) > 230
        if ies_field is not None:
            assert one_line(value).startswith(getattr(from_ies, ies_field))
        if value.isascii() and value.isprintable() and len(value) < 200 and \
                " ".join(value.split()) == value:
            assert keywords[key] == value
    # GLDF and L3D: XML holds every character the stage may hold
    if name == MANUFACTURER:
        assert doc["Header"]["Manufacturer"] == value
    elif name == CATALOGUE_NUMBER:
        assert doc["ProductDefinitions"]["ProductMetaData"]["UniqueProductId"] == value
    elif name == LAMP_DESCRIPTION:
        source = doc["GeneralDefinitions"]["LightSources"]["FixedLightSource"][0]
        assert source["Name"]["Locale"][0]["$text"] == value
    else:
        meta = doc["ProductDefinitions"]["ProductMetaData"]
        assert meta["Name"]["Locale"][0]["$text"] == shown == value
        assert structure["Header"]["Name"] == value


@FEW
@given(name=st.sampled_from((INPUT_POWER, COLOUR_RENDERING_INDEX)), number=NUMBER)
def test_any_number_is_refused_by_name_or_written_in_its_schemas_range(base, name, number):
    read, refused = _entered(name, number)
    if refused is not None or isinstance(read, StageError):
        _check_refusal(name, number, read, refused)
        assert not (math.isfinite(number) and 0.0 <= number and (
            name == INPUT_POWER or number <= 100.0))
        return
    info = read
    paths, gldf, l3d, shown = _written(base, info)
    ldt, from_ies, keywords, doc, _ = _check_files(base, paths, gldf, l3d, shown)
    source = doc["GeneralDefinitions"]["LightSources"]["FixedLightSource"][0]
    if name == INPUT_POWER:
        assert info.input_power_w == number
        assert source["RatedInputPower"] == number and ldt.lamp_watt == [
            pytest.approx(number, rel=1e-5)]
        assert read_ies(paths["ies"]).input_watts == pytest.approx(number, rel=1e-5)
    else:
        assert info.colour_rendering_index == number
        assert source["ColorInformation"]["ColorRenderingIndex"] == round(number)
        assert float(ldt.lamp_cri[0]) == pytest.approx(number, abs=0.005)  # 6 characters
        assert float(keywords["_CRI"]) == pytest.approx(number, rel=1e-5, abs=1e-5)
