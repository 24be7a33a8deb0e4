"""The luminous opening: measured without trimming light (the Lambertian disc's 100 mm, the
demo's diffuser, the louvre's cells), none where light leaves from everywhere (the Fresnel
slab: a warning, no luminance or UGR table), a declared one replacing the measured one in
the files, the tables and the record; the estimator's edges against synthetic exits whose
outline is known, and its errors against its spread over seeds."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pxr import Gf
from helpers.paths import REFERENCE, STAGES
from helpers.stages import with_attributes

from lumitrace.errors import OutputWarning
from lumitrace.photometry.distribution import photometry_of
from lumitrace.photometry.lm63 import read_ies
from lumitrace.photometry.eulumdat import read_ldt
from lumitrace.photometry.luminance import luminance_table
from lumitrace.photometry.opening import (EDGE_LEVEL, STRAY_LIMIT, measured_opening,
                                          opening_of_exits)
from lumitrace.photometry.tables import application_figures
from lumitrace.photometry.ugr import ugr_table
from lumitrace.publish.outputs import write_outputs
from lumitrace.run.session import TraceSettings, run
from lumitrace.stage.reader import read_stage

SETTINGS = TraceSettings(photons=200_000, seed=3, resolution=16, threads=2)


def _disc_exits(n: int, seed: int, radius: float = 0.05, glow: float = 0.0):
    """Exits of a uniformly lit disc (and a uniform glow of ``glow`` times its exitance
    over a square twice its size), on the bottom of a box 4 radii wide."""
    rng = np.random.default_rng(seed)
    r = radius * np.sqrt(rng.random(n))
    t = 2 * math.pi * rng.random(n)
    p = np.stack([r * np.cos(t), r * np.sin(t), np.zeros(n)], axis=1)
    if glow:
        m = rng.poisson(glow * n * (4 * radius ** 2 * 4) / (math.pi * radius ** 2))
        q = rng.uniform(-2 * radius, 2 * radius, (m, 2))
        p = np.concatenate([p, np.c_[q, np.zeros(m)]])
    lo, hi = (-2 * radius, -2 * radius, 0.0), (2 * radius, 2 * radius, 0.01)
    return p, np.full(len(p), 1.0 / n), lo, hi


def test_a_uniform_disc_is_measured_to_its_rim_with_honest_errors():
    """Over 24 synthetic draws: the diameter within 0.05% of its value, the stated error
    within a factor of two of the spread (mean squared z-score 0.25 to 4)."""
    runs = [opening_of_exits(*_disc_exits(32768, seed)) for seed in range(24)]
    d = np.array([o.length for o in runs])
    e = np.array([o.error[0] for o in runs])
    assert all(o.round and o.source == "measured" and o.length == o.width for o in runs)
    assert abs(d.mean() / 0.1 - 1.0) < 5e-4, d.mean()
    z2 = float((((d - 0.1) / e) ** 2).mean())
    assert 0.25 <= z2 <= 4.0, (z2, d.std(), e.mean())


def test_a_faint_glow_beyond_the_edge_is_not_the_opening():
    """A glow at a 25th of the edge level beyond a disc (0.2% of its exitance, 0.8% of its
    light) leaves its diameter (within 0.1%) and is counted as light outside it; five times
    as much is light from everywhere."""
    p, w, lo, hi = _disc_exits(65536, 1, glow=EDGE_LEVEL / 25)
    o = opening_of_exits(p, w, lo, hi)
    assert o.source == "measured" and o.length == pytest.approx(0.1, rel=1e-3)
    assert 0.0 < o.outside <= STRAY_LIMIT
    assert opening_of_exits(*_disc_exits(65536, 1, glow=EDGE_LEVEL / 5)).source == "none"


def test_a_rectangle_with_dark_bars_is_its_outline():
    """A rectangular opening crossed by dark blades (a louvre) is its outline, not its
    first cell: 240 x 120 mm within 0.05%."""
    rng = np.random.default_rng(2)
    x = rng.uniform(-0.12, 0.12, 200_000)
    y = rng.uniform(-0.06, 0.06, 200_000)
    blade = np.abs(((x + 0.12) % 0.0096) - 0.0048) < 0.0004  # 0.8 mm blades every 9.6 mm
    x, y = x[~blade], y[~blade]
    p = np.stack([x, y, np.zeros(len(x))], axis=1)
    o = opening_of_exits(p, np.ones(len(x)), (-0.128, -0.066, 0.0), (0.128, 0.066, 0.05))
    assert not o.round
    assert o.length == pytest.approx(0.24, rel=5e-4) and o.width == pytest.approx(0.12,
                                                                                   rel=5e-4)


@pytest.mark.parametrize("stage, size, shape", [
    # the disc's rim: radius 5 cm
    ("reference/lambertian_disc.usda", (0.100, 0.100), "round"),
    # the opal diffuser the light leaves through: a 48-gon through a circle of 124 mm
    # (123.7 mm across its sides), lit to its rim (its exitance fades from the middle
    # to a tenth at the rim, then stops)
    ("downlight.usda", (0.124, 0.124), "round"),
    # the louvre's cells: between the inner faces of its end blades (x = +-119.6 mm) and
    # of its side reflectors (y = +-60.5 mm); its blades' bottoms, inside, count, the
    # faint glow beyond its end blades (0.03% of the light) does not
    ("louvre.usda", (0.2392, 0.121), "rectangular"),
])
def test_the_stages_openings_are_measured_within_0_2_percent(stage, size, shape):
    scene = read_stage(STAGES / stage)
    o = measured_opening(scene, 1 << 16, seed=4)
    assert o.source == "measured" and o.shape == shape
    assert o.length == pytest.approx(size[0], rel=2e-3)
    assert o.width == pytest.approx(size[1], rel=2e-3)
    assert 0 < o.error[0] < 2e-3 * size[0] and o.outside < STRAY_LIMIT


def test_the_louvres_ends_give_its_luminous_height():
    """Light through the louvre's open ends (5% of it) leaves in a band 25 to 41.6 mm up
    (over its end blades, under its board and housing): its luminous height."""
    o = measured_opening(read_stage(STAGES / "louvre.usda"), 1 << 16, seed=4)
    assert 0.0155 <= o.height <= 0.0175, o.height


def test_the_discs_luminance_is_its_closed_form(tmp_path):
    """The Lambertian disc's luminance is Phi / (pi^2 r^2) in every direction: the table's
    within 3 standard errors, and the opening no longer makes it 1.4% high."""
    scene = read_stage(REFERENCE / "lambertian_disc.usda")
    result = run(scene, SETTINGS)
    ph = photometry_of(scene, result.accumulator, SETTINGS.seed)
    table = luminance_table(ph.grid, ph.opening)
    truth = 1000.0 / (math.pi ** 2 * 0.05 ** 2)
    z = (table.luminance - truth) / table.sigma
    assert np.abs(z).max() < 4.0 and abs(float(z.mean())) < 3.0 / math.sqrt(z.size) * 3


def test_the_fresnel_slab_has_no_opening(tmp_path):
    """Light leaves the slab's 40 m of glass from everywhere: no opening, a warning that
    names the attributes to declare one, no luminance or UGR table, no luminous area in
    the files."""
    scene = read_stage(REFERENCE / "fresnel_slab.usda")
    result = run(scene, SETTINGS)
    ph = photometry_of(scene, result.accumulator, SETTINGS.seed)
    assert ph.opening.source == "none" and not ph.opening.meaningful
    assert "lumitrace:luminousOpening" in ph.opening.note
    figures = application_figures(ph, result.accumulator)
    assert "ugr_table" not in figures and "luminance_table" not in figures
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        record = write_outputs(result, tmp_path, pictures=False, sublayer=False)
    said = [str(w.message) for w in caught if issubclass(w.category, OutputWarning)]
    assert any("not applicable" in s and "lumitrace:luminousOpeningShape" in s for s in said)
    assert record["luminous_opening_source"] == "none"
    assert record["ugr_table"] is None and record["luminance_table"] is None
    assert record["ugr_4h8h_70_50_20"] is None
    ies = read_ies(record["ies"])
    assert (ies.width, ies.length, ies.height) == (0.0, 0.0, 0.0)
    ldt = read_ldt(record["ldt"])
    assert ldt.dims_mm["lum_length"] == 0.0 and ldt.dims_mm["lum_width"] == 0.0


def _declared(tmp_path, src, shape, size_mm):
    return with_attributes(src, tmp_path / src.name, {
        "lumitrace:luminousOpeningShape": ("token", shape),
        "lumitrace:luminousOpening": ("double3", Gf.Vec3d(*size_mm))})


def test_a_declared_opening_replaces_the_measured_one(tmp_path):
    """The slab declared 100 mm round (in a stage of metres: 0.1): the record says
    declared, the files carry it, the tables are made with it."""
    stage = _declared(tmp_path, REFERENCE / "fresnel_slab.usda", "round", (0.1, 0.1, 0.0))
    scene = read_stage(stage)
    result = run(scene, SETTINGS)
    ph = photometry_of(scene, result.accumulator, SETTINGS.seed)
    o = ph.opening
    assert (o.source, o.round, o.length, o.width, o.height) == ("declared", True, 0.1, 0.1, 0)
    assert o.error == (0.0, 0.0, 0.0)
    record = write_outputs(result, tmp_path / "out", pictures=False)
    assert record["luminous_opening_source"] == "declared"
    assert tuple(record["luminous_opening"]) == (0.1, 0.1, 0.0)
    table = ugr_table(ph.grid, o)
    assert record["ugr_4h8h_70_50_20"] == pytest.approx(table.catalogue()[0], abs=1e-4)
    ies = read_ies(record["ies"])
    assert ies.width == pytest.approx(-0.1) and ies.length == pytest.approx(-0.1)
    ldt = read_ldt(record["ldt"])
    assert ldt.dims_mm["lum_length"] == pytest.approx(100.0) and ldt.dims_mm["lum_width"] == 0


def test_a_declared_rectangle_in_stage_units(tmp_path):
    """A declared rectangle on the louvre (stage in mm): metres in the record, length along
    C0 and width along C90 as declared."""
    stage = _declared(tmp_path, STAGES / "louvre.usda", "rectangular", (240.0, 120.0, 0.0))
    o = photometry_of(read_stage(stage), run(read_stage(stage), TraceSettings(
        photons=20_000, seed=1, resolution=16, threads=2)).accumulator).opening
    assert (o.source, o.round) == ("declared", False)
    assert (o.length, o.width, o.height) == pytest.approx((0.24, 0.12, 0.0))


def _turned_louvre(tmp_path):
    """The louvre turned a quarter inside its luminaire prim: long along C90, as EULUMDAT
    has a linear luminaire."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(tmp_path / "turned.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.001)
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(root.GetPrim())
    inner = UsdGeom.Xform.Define(stage, "/Luminaire/Louvre")
    inner.AddRotateZOp().Set(90.0)
    inner.GetPrim().GetReferences().AddReference(str(STAGES / "louvre.usda"))
    stage.GetRootLayer().Save()
    return tmp_path / "turned.usda"


_RECORDS: dict = {}


@pytest.mark.parametrize("turned", [False, True])
def test_a_linear_luminaire_is_linear_in_the_ldt(tmp_path, turned):
    """The louvre (239 x 121 mm) is linear: EULUMDAT's Ityp 2, its length along C90; as
    modelled (long along C0) the file's length is its C90 extent and a warning says a
    reader names crosswise and endwise the other way round; turned to C90, no warning and
    the file's length is its long side. Either way the datasheet's crosswise is the same."""
    pyldt = pytest.importorskip("pyldt")
    stage = _turned_louvre(tmp_path) if turned else STAGES / "louvre.usda"
    result = run(read_stage(stage), TraceSettings(photons=60_000, seed=2, resolution=8,
                                                  threads=2))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        record = write_outputs(result, tmp_path / "out", pictures=False, sublayer=False)
    said = [str(w.message) for w in caught if "linear luminaire long along C0" in
            str(w.message)]
    ldt = pyldt.LdtReader.read(str(record["ldt"])).header
    assert ldt.ityp == 2 and read_ldt(record["ldt"]).ityp == 2
    long_side, short_side = sorted(record["luminous_opening"][:2], reverse=True)
    if turned:
        assert not said and record["ugr_table"]["long_axis"] == "C90"
        assert ldt.length_lum_area == pytest.approx(1000 * long_side, abs=0.01)
    else:
        assert len(said) == 1 and record["ugr_table"]["long_axis"] == "C0"
        assert ldt.length_lum_area == pytest.approx(1000 * short_side, abs=0.01)
    _RECORDS[turned] = record
    if len(_RECORDS) == 2:  # crosswise the long side across the line of sight, either way
        a, b = _RECORDS[False], _RECORDS[True]
        for key in ("ugr_4h8h_70_50_20", "ugr_4h8h_70_50_20_endwise"):
            sigma = math.hypot(a[key + "_error"], b[key + "_error"])
            assert abs(a[key] - b[key]) < 4 * sigma + 0.05, (key, a[key], b[key])
    variation = record["ugr_observer_variation"]
    assert variation["spacing_h"] == [1.0, 1.5, 2.0] and variation["room_h"] == [4, 8]
    assert record["ugr_lamp_flux"] == pytest.approx(4000.0)


def test_a_round_luminaire_is_not_linear(tmp_path):
    pyldt = pytest.importorskip("pyldt")
    result = run(read_stage(REFERENCE / "lambertian_disc.usda"), SETTINGS)
    record = write_outputs(result, tmp_path / "out", pictures=False, sublayer=False)
    assert pyldt.LdtReader.read(str(record["ldt"])).header.ityp == 1  # rotational
    assert record["ugr_table"]["long_axis"] == ""


def test_the_datasheet_says_the_tables_are_not_applicable():
    from lumitrace.publish.datasheet_content import (luminance_section, opening_cell,
                                                      ugr_section)

    record = {"luminous_opening": (0.0, 0.0, 0.0), "luminous_opening_source": "none",
              "luminous_opening_note": "no luminous opening: light from everywhere",
              "ugr_table": None, "luminance_table": None}
    for section in (ugr_section(record), luminance_section(record)):
        assert section.rows[0][0].text == "not applicable"
        assert section.note == record["luminous_opening_note"]
    assert opening_cell(record).text.startswith("none")
    declared = {**record, "luminous_opening": (0.1, 0.1, 0.0),
                "luminous_opening_source": "declared", "luminous_opening_shape": "round"}
    assert opening_cell(declared).text == "100.00 x 100.00 x 0.00 (round, declared)"
    assert ugr_section({}) is None  # no opening said, no table: nothing to show


def test_a_point_source_has_no_opening():
    """All exits at one point (a light treated as a point, its box of no extent): no
    luminous area, no opening, said."""
    p = np.zeros((5000, 3))
    o = opening_of_exits(p, np.ones(5000), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert o.source == "none" and not o.meaningful and "a point or a line" in o.note
