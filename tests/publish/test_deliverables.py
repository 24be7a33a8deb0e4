"""The deliverables (``trace --deliverables``, ``lumitrace datasheet``): the GLDF container
validated against the GLDF and L3D XML schemas and read back by third-party readers
(``gldf-rs-python``, ``l3d-rs-python``, ``pyldt``), its photometry byte for byte our LDT;
the datasheet's PDF rendered to pages by ``pdftoppm`` and every figure on its HTML page
equal to the result record's; the zonal flux of a Lambertian disc against its closed form."""
from __future__ import annotations

import io
import json
import math
import shutil
import subprocess
import sys
import zipfile
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from helpers.paths import ROOT
from helpers.stages import with_attributes

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)

REFERENCE = ROOT.parent / "shared" / "reference"
GLDF_XSD, L3D_XSD = REFERENCE / "gldf" / "gldf.xsd", REFERENCE / "l3d" / "l3d.xsd"
INFO = {"lumitrace:manufacturer": ("string", "Acme Lighting GmbH"),
        "lumitrace:luminaireName": ("string", "Downlight 120 Reflector"),
        "lumitrace:catalogueNumber": ("string", "AL-DL120-840"),
        "lumitrace:lampDescription": ("string", "LED module 840"),
        "lumitrace:inputPower": ("double", 13.5),
        "lumitrace:colourRenderingIndex": ("double", 82.0),
        "lumitrace:author": ("string", "Photometry lab, Acme")}


def _lumitrace(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lumitrace", *args], capture_output=True,
                          text=True, timeout=300)


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The demo with the luminaire's data, traced with the deliverables: (stage, the
    --json summary)."""
    stage = with_attributes(ROOT / "stages" / "downlight.usda",
                            tmp_path_factory.mktemp("deliverables") / "dl.usda", INFO)
    p = _lumitrace("trace", str(stage), "--photons", "300000", "--resolution", "16",
                   "--no-progress", "--no-pictures", "--deliverables", "--json")
    assert p.returncode == 0, p.stderr
    return stage, json.loads(p.stdout.strip().splitlines()[-1])


def _flat(summary: dict) -> dict:
    """The record's keys and values from the --json summary (groups un-nested)."""
    out = {}
    for k, v in summary.items():
        out.update(v if k in ("outputs", "photometry", "colour") else {k: v})
    return out


def _container(summary) -> zipfile.ZipFile:
    return zipfile.ZipFile(summary["outputs"]["gldf"])


def _l3d(summary) -> bytes:
    z = _container(summary)
    return z.read(next(n for n in z.namelist() if n.endswith(".l3d")))


def _schema(path: Path):
    xmlschema = pytest.importorskip("xmlschema")
    if not path.is_file():
        pytest.skip(f"the XML schema {path.name} is not in ../shared/reference next to the "
                    "repository (the GLDF and L3D schemas the container is checked against)")
    return xmlschema.XMLSchema(str(path))


def test_product_xml_is_valid_gldf(demo):
    schema = _schema(GLDF_XSD)
    xml = _container(demo[1]).read("product.xml").decode()
    errors = [f"{e.path}: {e.reason}" for e in schema.iter_errors(xml)]
    assert errors == []


def test_structure_xml_is_valid_l3d(demo):
    schema = _schema(L3D_XSD)
    xml = zipfile.ZipFile(io.BytesIO(_l3d(demo[1]))).read("structure.xml").decode()
    assert [f"{e.path}: {e.reason}" for e in schema.iter_errors(xml)] == []


def test_gldf_rs_reads_the_product_and_its_file_references(demo, tmp_path):
    gldf = pytest.importorskip("gldf_rs_python")
    stage, summary = demo
    doc = json.loads(gldf.gldf_to_json(summary["outputs"]["gldf"]))
    assert doc["Header"]["Manufacturer"] == "Acme Lighting GmbH"
    meta = doc["ProductDefinitions"]["ProductMetaData"]
    assert meta["UniqueProductId"] == "AL-DL120-840"
    assert meta["Name"]["Locale"][0]["$text"] == "Downlight 120 Reflector"
    general = doc["GeneralDefinitions"]
    source = general["LightSources"]["FixedLightSource"][0]
    assert source["RatedInputPower"] == 13.5
    assert source["ColorInformation"]["ColorRenderingIndex"] == 82
    assert source["Name"]["Locale"][0]["$text"] == "LED module 840"
    files = {f["@contentType"]: f["$text"] for f in general["Files"]["File"]}
    names = zipfile.ZipFile(summary["outputs"]["gldf"]).namelist()
    folders = {"ldc/eulumdat": "ldc", "ldc/ies": "ldc", "geo/l3d": "geo",
               "document/pdf": "doc"}
    for kind, folder in folders.items():
        assert f"{folder}/{files[kind]}" in names  # every referenced file is there
    assert files["ldc/eulumdat"] == "dl.ldt" and files["document/pdf"] == "dl.datasheet.pdf"
    photometry = general["Photometries"]["Photometry"][0]
    assert photometry["PhotometryFileReference"]["@fileId"] == "file_ldt"
    figures = photometry["DescriptivePhotometry"]
    ph = summary["photometry"]
    assert figures["LightOutputRatio"] == summary["light_output_ratio"]
    assert figures["LuminousEfficacy"] == ph["luminous_flux"] / 13.5
    assert figures["CIE-FluxCode"] == ph["cie_flux_code"]
    assert figures["LightDistributionBUG-Rating"] == ph["bug_rating"]
    # GLDF's X is lengthways (endwise), its Y across (crosswise)
    assert figures["UGR-4H8H-70-50-20-LQ"] == {"X": ph["ugr_4h8h_70_50_20_endwise"],
                                                "Y": ph["ugr_4h8h_70_50_20"]}
    emitter = general["Emitters"]["Emitter"][0]["FixedLightEmitter"][0]
    # GLDF: the emitter's rated flux is the entire equipment's, the luminaire's output; the
    # lamps' flux is the LDT's lamp set, which its photometry is relative to
    assert emitter["RatedLuminousFlux"] == round(ph["luminous_flux"])
    assert source["Manufacturer"] == "Acme Lighting GmbH"
    assert doc["Header"]["Author"] == "Photometry lab, Acme"
    variant = doc["ProductDefinitions"]["Variants"]["Variant"][0]
    ref = variant["Geometry"]["ModelGeometryReference"]["EmitterReference"][0]
    assert ref["EmitterObjectExternalName"] == "leo_opening"


def test_the_containers_photometry_is_our_ldt(demo):
    pyldt = pytest.importorskip("pyldt")
    stage, summary = demo
    inside = _container(summary).read("ldc/dl.ldt")
    assert inside == Path(summary["outputs"]["ldt"]).read_bytes()
    extracted = stage.with_name("from_container.ldt")
    extracted.write_bytes(inside)
    ldt = pyldt.LdtReader.read(str(extracted))
    grid = json.loads(Path(summary["outputs"]["photometry_data"]).read_text())
    assert ldt.header.luminaire_name == "Downlight 120 Reflector"
    # one C plane (rotational symmetry) in cd/klm of the lamp flux, as the grid says
    per_klm = 1000.0 / summary["photometry"]["lamp_flux"]
    expected = np.asarray(grid["candela"])[0] * per_klm
    got = np.asarray(ldt.intensities[0], dtype=float)
    assert got == pytest.approx(expected, rel=1e-3, abs=0.05)


def test_l3d_rs_reads_the_geometry_and_the_light_emitting_object(demo):
    l3d = pytest.importorskip("l3d")
    from lumitrace.stage.reader import read_stage

    stage, summary = demo
    data = _l3d(summary)
    doc = json.loads(l3d.parse_l3d(data))
    parts = json.loads(l3d.get_model_parts(data))
    assert [p["path"] for p in parts] == ["luminaire/luminaire.obj"]
    structure = json.loads(l3d.parse_structure_xml(doc["file"]["structure"]))
    geometry = structure["Structure"]["Geometry"]
    leo = geometry["LightEmittingObjects"]["LightEmittingObject"][0]
    opening = summary["photometry"]["luminous_opening"]
    assert leo["@partName"] == "leo_opening"
    assert leo["Circle"]["@diameter"] == pytest.approx(0.5 * (opening[0] + opening[1]),
                                                       rel=1e-6)
    # the OBJ holds the stage's triangles, in metres in the photometric frame (z up)
    scene = read_stage(stage)
    obj = zipfile.ZipFile(io.BytesIO(data)).read("luminaire/luminaire.obj").decode()
    v = np.array([line.split()[1:] for line in obj.splitlines() if line.startswith("v ")],
                 dtype=float)
    faces = [line for line in obj.splitlines() if line.startswith("f ")]
    world = scene.triangles.reshape(-1, 3) @ np.asarray(scene.photometric_axes).T
    assert v.min(axis=0) == pytest.approx(world.min(axis=0), abs=1e-8)
    assert v.max(axis=0) == pytest.approx(world.max(axis=0), abs=1e-8)
    assert len(faces) <= len(scene.triangles) and len(faces) > 0.99 * len(scene.triangles)
    groups = [line.split()[1] for line in obj.splitlines() if line.startswith("g ")]
    assert sorted(groups) == sorted(p.rsplit("/", 1)[-1] for p in scene.parts)


def test_the_datasheet_pdf_renders_to_one_or_two_pages(demo, tmp_path):
    if shutil.which("pdftoppm") is None:
        pytest.skip("pdftoppm (poppler-utils) is not installed: setup.sh --test installs it")
    pdf = demo[1]["outputs"]["datasheet_pdf"]
    p = subprocess.run(["pdftoppm", "-r", "30", "-png", pdf, str(tmp_path / "page")],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    pages = sorted(tmp_path.glob("page*.png"))
    assert 1 <= len(pages) <= 2
    assert all(q.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for q in pages)


class _Cells(HTMLParser):
    """The ``data-key``/``data-value`` cells and the embedded record of a datasheet."""

    def __init__(self):
        super().__init__()
        self.cells, self.record, self._in_record, self._text = [], None, False, None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "data-key" in a:
            self.cells.append([a["data-key"], json.loads(a["data-value"]), ""])
            self._text = self.cells[-1]
        self._in_record = a.get("id") == "lumitrace-record"

    def handle_endtag(self, tag):
        self._text = None

    def handle_data(self, data):
        if self._text is not None:
            self._text[2] += data
        if self._in_record:
            self.record = json.loads(data)
            self._in_record = False


def _value(record: dict, key: str):
    """``record``'s value at ``key``: ``zonal_flux[3]`` (the zone's lm), ``a.b[i][j]``."""
    head, *path = key.replace("]", "").split("[")
    parts = head.split(".")
    v = record[parts[0]]
    for p in parts[1:]:
        v = v[p]
    for i in path:
        v = v[int(i)]
    return v[2] if parts[0] == "zonal_flux" else v


def _cells(path) -> _Cells:
    parser = _Cells()
    parser.feed(Path(path).read_text())
    return parser


def test_every_figure_on_the_html_page_is_the_records(demo):
    stage, summary = demo
    record = _flat(summary)
    page = _cells(summary["outputs"]["datasheet_html"])
    keys = {k for k, _, _ in page.cells}
    assert {"luminous_flux", "light_output_ratio", "peak_intensity", "beam_angle_c0_c180",
            "field_angle_c90_c270", "cie_flux_code", "downward_flux_fraction", "photons",
            "seed", "relative_error", "relative_error_bound", "input_hash",
            "zonal_flux[0]"} <= keys
    assert any(k.startswith("ugr_table.") for k in keys)
    assert any(k.startswith("luminance_table.") for k in keys)
    for key, value, text in page.cells:
        assert value == _value(record, key), key
    shown = {k: t for k, _, t in page.cells}
    assert shown["photons"] == "300,000" and shown["cie_flux_code"] == record["cie_flux_code"]
    flux, err = record["luminous_flux"], record["luminous_flux_error"]
    d = max(1 - math.floor(math.log10(err)), 0)  # two significant digits of the error
    assert shown["luminous_flux"] == f"{flux:,.{d}f} ± {err:,.{d}f} lm"
    assert page.record == {k: record[k] for k in page.record}  # the embedded record
    # the zones add up to the luminaire's flux
    zones = record["zonal_flux"]
    assert sum(z[2] for z in zones) == pytest.approx(flux, rel=1e-12)


def test_the_datasheet_command_reproduces_the_published_record(demo, tmp_path):
    stage, summary = demo
    p = _lumitrace("datasheet", str(stage), "--out", str(tmp_path), "--json")
    assert p.returncode == 0, p.stderr
    said = json.loads(p.stdout.strip().splitlines()[-1])
    assert said["from_published"] is True and said["input_hash"] == summary["input_hash"]
    ours = {k: v for k, v, _ in _cells(said["datasheet_html"]).cells}
    theirs = {k: v for k, v, _ in _cells(summary["outputs"]["datasheet_html"]).cells}
    assert ours == theirs  # same photons, same seed: the same figures exactly


def test_the_datasheet_command_traces_a_stage_without_a_current_result(tmp_path):
    stage = tmp_path / "iso.usda"
    shutil.copy(ROOT / "stages" / "reference" / "isotropic.usda", stage)
    p = _lumitrace("datasheet", str(stage), "--photons", "20000", "--seed", "4", "--json")
    assert p.returncode == 0, p.stderr
    said = json.loads(p.stdout.strip().splitlines()[-1])
    assert said["from_published"] is False and said["status"] == "missing"
    page = _cells(said["datasheet_html"])
    values = {k: v for k, v, _ in page.cells}
    assert values["photons"] == 20000 and values["seed"] == 4
    assert "traced for this datasheet, not published" in \
        Path(said["datasheet_html"]).read_text()
    assert Path(said["datasheet_html"]).parent == tmp_path / "iso.datasheet"
    # nothing of the stage's outputs is written
    assert sorted(q.name for q in tmp_path.iterdir()) == ["iso.datasheet", "iso.usda"]


def test_zonal_flux_of_a_lambertian_disc_is_the_closed_form():
    from lumitrace.photometry.measured import emitter_rings
    from lumitrace.photometry.zonal import zonal_flux
    from lumitrace.run.session import TraceSettings, run
    from lumitrace.stage.reader import read_stage

    scene = read_stage(ROOT / "stages" / "reference" / "lambertian_disc.usda")
    r = run(scene, TraceSettings(photons=200_000, resolution=8, seed=3, threads=2))
    zones = zonal_flux(emitter_rings(r.accumulator))
    total = scene.total_flux
    for lo, hi, lm, err in zones:
        # a downward Lambertian emitter: flux within gamma is total sin^2(gamma)
        a, b = math.radians(min(lo, 90.0)), math.radians(min(hi, 90.0))
        expected = total * (math.sin(b) ** 2 - math.sin(a) ** 2)
        if expected == 0.0:
            assert lm == 0.0 and err == 0.0
        else:
            p = expected / total
            assert err == pytest.approx(total * math.sqrt(p * (1 - p) / 200_000), rel=0.05)
            assert abs(lm - expected) < 4 * err


def test_the_cartesian_diagram_is_for_narrow_beams():
    from lumitrace.photometry.curves import is_narrow

    assert is_narrow({"beam_angle_c0_c180": 24.0, "beam_angle_c90_c270": 80.0})
    assert not is_narrow({"beam_angle_c0_c180": 120.0, "beam_angle_c90_c270": 119.0})
    assert not is_narrow({"beam_angle_c0_c180": None, "beam_angle_c90_c270": None})


def test_a_bare_light_and_a_rectangular_opening_make_valid_l3d():
    l3d = pytest.importorskip("l3d")
    from lumitrace.photometry.distribution import LuminousOpening
    from lumitrace.publish.l3d import l3d_bytes
    from lumitrace.stage.reader import read_stage

    schema = _schema(L3D_XSD)
    bare = read_stage(ROOT / "stages" / "reference" / "isotropic.usda")
    opening = LuminousOpening(0.3, 0.1, 0.0, (0.01, -0.02, -0.05))
    data = l3d_bytes(bare, opening, "bare light")
    xml = zipfile.ZipFile(io.BytesIO(data)).read("structure.xml").decode()
    assert [e.reason for e in schema.iter_errors(xml)] == []
    structure = json.loads(l3d.parse_structure_xml(xml))
    leo = structure["Structure"]["Geometry"]["LightEmittingObjects"]["LightEmittingObject"][0]
    assert leo["Rectangle"] == {"@sizeX": 0.3, "@sizeY": 0.1} and leo["Circle"] is None
    assert (leo["Position"]["@x"], leo["Position"]["@y"], leo["Position"]["@z"]) == \
        pytest.approx((0.01, -0.02, -0.05))
    obj = zipfile.ZipFile(io.BytesIO(data)).read("luminaire/luminaire.obj").decode()
    v = np.array([line.split()[1:] for line in obj.splitlines() if line.startswith("v ")],
                 dtype=float)
    assert bare.triangles.size == 0  # no geometry: a stand-in box the opening's size
    assert v.max(axis=0) - v.min(axis=0) == pytest.approx((0.3, 0.1, 0.01))


def test_what_the_stage_does_not_say_is_left_out_and_said(tmp_path):
    """A stage with none of the luminaire's data: the GLDF is valid without the light
    source's manufacturer and the author (optional), keeps the required manufacturer and
    power as placeholders, and writing it warns, naming the attributes to author."""
    import warnings

    from lumitrace.errors import OutputWarning
    from lumitrace.publish.outputs import write_outputs
    from lumitrace.run.session import TraceSettings, run
    from lumitrace.stage.reader import read_stage

    gldf = pytest.importorskip("gldf_rs_python")
    stage = tmp_path / "disc.usda"
    shutil.copy(ROOT / "stages" / "reference" / "lambertian_disc.usda", stage)
    result = run(read_stage(stage), TraceSettings(photons=50_000, resolution=8, threads=2))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        record = write_outputs(result, tmp_path, pictures=True, deliverables=True,
                               sublayer=False)
    said = [str(w.message) for w in caught if issubclass(w.category, OutputWarning)]
    missing = [s for s in said if "author lumitrace:manufacturer" in s]
    assert len(missing) == 1, said
    for name in ("lumitrace:inputPower", "lumitrace:author", "unknown manufacturer", "0 W"):
        assert name in missing[0]
    xml = zipfile.ZipFile(record["gldf"]).read("product.xml").decode()
    assert [f"{e.path}: {e.reason}" for e in _schema(GLDF_XSD).iter_errors(xml)] == []
    assert "<Author>" not in xml
    doc = json.loads(gldf.gldf_to_json(record["gldf"]))
    source = doc["GeneralDefinitions"]["LightSources"]["FixedLightSource"][0]
    assert "Manufacturer" not in source or source["Manufacturer"] in (None, "")
    assert source["RatedInputPower"] == 0.0  # required by the schema: said in the warning
    assert doc["Header"]["Manufacturer"] == "unknown manufacturer"  # required likewise
    assert "LuminousEfficacy" not in json.dumps(doc)


def test_the_summary_prints_the_opening_the_datasheet_and_the_gldf(demo):
    """The text summary of a run with --deliverables: their paths, as --json has them."""
    from lumitrace.publish.record import ResultRecord
    from lumitrace.report.console import summary_text

    stage, summary = demo
    flat = {k: v for k, v in _flat(summary).items() if k not in ("target_reached", "warnings")}
    text = summary_text(ResultRecord(flat), stage)
    outputs = summary["outputs"]
    assert outputs["gldf"] and outputs["datasheet_html"] and outputs["datasheet_pdf"]
    assert f"GLDF            {outputs['gldf']}" in text
    assert f"datasheet       {outputs['datasheet_html']}  {outputs['datasheet_pdf']}" in text
    assert "(round, measured)" in text


def test_an_observer_variation_it_could_not_read_is_a_dash_in_the_table():
    """Few photons of a narrow beam (the fit's candidates): a rise or fall of the observer
    variation undefined is written "-", not a failed datasheet."""
    from lumitrace.publish.datasheet_content import ugr_section

    table = {"reflectances": ["70/50/20"], "rooms_h": [[4, 8]], "crosswise": [[20.1]],
             "endwise": [[20.4]], "crosswise_error": [[0.1]], "spacing_h": 0.25}
    variation = {"spacing_h": [1.0, 1.5], "crosswise": [[0.4, None], [0.6, -0.2]],
                 "endwise": [[None, None], [0.5, -0.3]]}
    section = ugr_section({"ugr_table": table, "ugr_observer_variation": variation})
    texts = [cell.text for row in section.rows for cell in row]
    assert "+0.4 / -  ·  - / -" in texts and "+0.6 / -0.2  ·  +0.5 / -0.3" in texts
