"""``lumitrace sweep``: three reference stages and the two variants of a stage's variant
set give the table, the overview and per-variant outputs; a rerun traces nothing; a stage
changed is the only one traced again."""
import csv
import json
import os
import shutil
import subprocess
import sys
import time

import pytest
from helpers.paths import REFERENCE, ROOT, STAGES

REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
ARGS = ("--photons", "20000", "--resolution", "8", "--threads", "1", "--json")


def _sweep(folder, *extra):
    r = subprocess.run([sys.executable, "-m", "lumitrace", "sweep", str(folder), *ARGS,
                        "--out", str(folder / "out"), *extra], capture_output=True,
                       text=True, cwd=ROOT, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT / "service")})
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.splitlines()[-1])


def _finishes(path):
    """A copy of the demo with a variant set "finish" of two reflector roughnesses."""
    import lumitrace  # noqa: F401  (registers the schema before USD composes a stage)
    from pxr import Usd

    shutil.copy(STAGES / "downlight.usda", path)
    stage = Usd.Stage.Open(str(path))
    stage.GetPrimAtPath(REFLECTOR).GetAttribute("lumitrace:roughness").Clear()  # the
    # root layer's own opinion would be stronger than the variants'
    vs = stage.GetDefaultPrim().GetVariantSets().AddVariantSet("finish")
    for name, roughness in (("satin", 0.3), ("polished", 0.02)):
        vs.AddVariant(name)
        vs.SetVariantSelection(name)
        with vs.GetVariantEditContext():
            stage.GetPrimAtPath(REFLECTOR).GetAttribute("lumitrace:roughness").Set(roughness)
    vs.SetVariantSelection("satin")
    stage.GetRootLayer().Save()


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sweep")
    for name in ("isotropic", "lambertian_disc", "fresnel_slab"):
        shutil.copy(REFERENCE / f"{name}.usda", folder)
    _finishes(folder / "downlight.usda")
    before = (folder / "downlight.usda").read_bytes()
    first = _sweep(folder)
    return folder, first, before


def test_a_sweep_writes_the_table_the_overview_and_each_variants_outputs(swept):
    from lumitrace.report.sweep import Case, read_case

    folder, first, before = swept
    out = folder / "out"
    rows = {(os.path.basename(r["stage"]), r["variant"]): r for r in first["rows"]}
    assert set(rows) == {("downlight.usda", "finish=satin"), ("downlight.usda",
                         "finish=polished"), ("isotropic.usda", ""),
                         ("lambertian_disc.usda", ""), ("fresnel_slab.usda", "")}
    assert all(r["traced"] and r["photons"] == 20_000 for r in rows.values())
    for sub in ("downlight/finish-satin", "downlight/finish-polished", "isotropic"):
        name = sub.split("/")[0]
        assert {f"{name}{s}" for s in (".ies", ".ldt", ".intensity.exr", ".lumitrace.usda")} \
            <= set(os.listdir(out / sub))
    assert (folder / "downlight.usda").read_bytes() == before  # never sublayered into
    satin, polished = rows["downlight.usda", "finish=satin"], \
        rows["downlight.usda", "finish=polished"]
    assert satin["input_hash"] != polished["input_hash"]
    assert satin["peak_intensity"] != polished["peak_intensity"]
    # each variant's outputs are its own scene's: the result layer's hash is the variant's
    scene = read_case(Case(folder / "downlight.usda", (("finish", "polished"),), out))
    assert [a for a in REFLECTOR_ROUGHNESS(scene)] == [pytest.approx(0.02)]
    layer = (out / "downlight" / "finish-polished" / "downlight.lumitrace.usda").read_text()
    assert f'lumitrace:result:sceneHash = "{scene.content_hash()}"' in layer
    with open(out / "sweep.csv") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 5 and {r["variant"] for r in table} >= {"finish=satin"}
    iso = next(r for r in table if r["stage"].endswith("isotropic.usda"))
    assert float(iso["luminous_flux"]) == pytest.approx(1000.0)  # all of it leaves
    assert float(iso["light_output_ratio"]) == 1.0 and iso["light_output_ratio_error"]
    page = (out / "index.html").read_text()
    # each case drawn on the common scale and on its own, two planes each
    assert page.count("<svg") == 10 and page.count("<polyline") == 20
    assert "finish=polished" in page


def REFLECTOR_ROUGHNESS(scene):
    """Roughnesses of the scene's glossy materials."""
    return [m.roughness for m in scene.materials if m.scattering == "glossy"]


def test_a_rerun_traces_nothing_and_a_changed_stage_alone_is_traced_again(swept):
    from pxr import Sdf

    folder, first, _ = swept
    again = _sweep(folder)
    assert not any(r["traced"] for r in again["rows"])
    strip = lambda rows: sorted((r["key"], r["input_hash"], r["photons"]) for r in rows)  # noqa
    assert strip(again["rows"]) == strip(first["rows"])
    layer = Sdf.Layer.FindOrOpen(str(folder / "isotropic.usda"))
    layer.GetAttributeAtPath("/Luminaire/Source.lumitrace:luminousFlux").default = 900.0
    layer.Save()
    third = _sweep(folder)
    traced = {os.path.basename(r["stage"]) for r in third["rows"] if r["traced"]}
    assert traced == {"isotropic.usda"}
    iso = next(r for r in third["rows"] if r["traced"])
    assert iso["luminous_flux"] == pytest.approx(900.0)


def test_variants_named_narrow_the_sweep(swept, tmp_path):
    from lumitrace.errors import LumitraceError
    from lumitrace.report.sweep import parse_variants, plan

    folder, _, _ = swept
    cases = plan([folder / "downlight.usda"], parse_variants(["finish=polished"]), tmp_path)
    assert [(c.variants, c.folder.name) for c in cases] == [
        ((("finish", "polished"),), "finish-polished")]
    with pytest.raises(LumitraceError, match="has no variant 'matte' \\(it has "):
        plan([folder / "downlight.usda"], parse_variants(["finish=matte"]), tmp_path)
    with pytest.raises(LumitraceError, match="no stage of the sweep has a variant set 'lens'"):
        plan([folder / "isotropic.usda"], parse_variants(["lens"]), tmp_path)


def test_a_sweep_interrupted_picks_up_where_it_stopped(tmp_path):
    """SIGINT while the second stage (a long one) traces: exit 130 with the first stage's
    row in the table; started again, the sweep traces only the second."""
    import signal

    shutil.copy(REFERENCE / "isotropic.usda", tmp_path / "a.usda")  # quick
    shutil.copy(REFERENCE / "integrating_sphere.usda", tmp_path / "b.usda")  # long paths
    args = [sys.executable, "-m", "lumitrace", "sweep", str(tmp_path), "--photons", "4e6",
            "--resolution", "8", "--threads", "1", "--out", str(tmp_path / "out")]
    env = {**os.environ, "PYTHONPATH": str(ROOT / "service")}
    p = subprocess.Popen(args, stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env)
    for line in p.stderr:  # a line per case
        if line.startswith("[1/2] a.usda"):
            break
    time.sleep(0.5)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 128 + signal.SIGINT, err
    rows = json.loads((tmp_path / "out" / "sweep.json").read_text())["rows"]
    assert [os.path.basename(r["stage"]) for r in rows] == ["a.usda"]
    shutil.copy(REFERENCE / "lambertian_disc.usda", tmp_path / "b.usda")  # quick now
    again = subprocess.run([*args, "--json"], capture_output=True, text=True, cwd=ROOT,
                           env=env, timeout=300)
    assert again.returncode == 0, again.stderr
    rows = json.loads(again.stdout.splitlines()[-1])["rows"]
    assert [(os.path.basename(r["stage"]), r["traced"]) for r in rows] == [
        ("a.usda", False), ("b.usda", True)]


def _flux_variants(path, fluxes: dict):
    """A copy of the Lambertian disc with a variant set "output" of the source's flux."""
    import lumitrace  # noqa: F401
    from pxr import Sdf, Usd

    shutil.copy(REFERENCE / "lambertian_disc.usda", path)
    stage = Usd.Stage.Open(str(path))
    vs = stage.GetDefaultPrim().GetVariantSets().AddVariantSet("output")
    for name, flux in fluxes.items():
        vs.AddVariant(name)
        vs.SetVariantSelection(name)
        with vs.GetVariantEditContext():
            stage.GetPrimAtPath("/Luminaire/Source").CreateAttribute(
                "lumitrace:luminousFlux", Sdf.ValueTypeNames.Float).Set(flux)
    stage.GetPrimAtPath("/Luminaire/Source").GetAttribute("lumitrace:luminousFlux").Clear()
    stage.GetRootLayer().Save()


def test_a_bad_variant_is_one_failed_case_and_the_others_run(tmp_path):
    """A variant whose flux the stage reader refuses: that case fails, named with its stage,
    variant and reason, in the table and on stderr; the other cases are traced; exit 1."""
    _flux_variants(tmp_path / "lamps.usda", {"broken": -1.0, "good": 500.0})
    shutil.copy(REFERENCE / "isotropic.usda", tmp_path / "iso.usda")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "lumitrace", "sweep", str(tmp_path), *ARGS,
                        "--out", str(out)], capture_output=True, text=True, cwd=ROOT,
                       timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT / "service")})
    assert r.returncode == 1, r.stderr
    said = json.loads(r.stdout.splitlines()[-1])
    rows = {(os.path.basename(x["stage"]), x["variant"]): x for x in said["rows"]}
    assert set(rows) == {("lamps.usda", "output=broken"), ("lamps.usda", "output=good"),
                         ("iso.usda", "")} and said["failed"] == 1
    broken = rows["lamps.usda", "output=broken"]
    assert broken["error"].startswith("lamps.usda [output=broken]: ")
    assert "/Luminaire/Source.lumitrace:luminousFlux" in broken["error"]
    assert not broken["traced"]
    assert rows["lamps.usda", "output=good"]["luminous_flux"] == pytest.approx(500.0)
    assert rows["iso.usda", ""]["photons"] == 20_000
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("lumitrace: error")]
    assert errors == [f"lumitrace: error: {broken['error']}"]
    with open(out / "sweep.csv") as f:
        table = {(os.path.basename(x["stage"]), x["variant"]): x for x in csv.DictReader(f)}
    assert table["lamps.usda", "output=broken"]["error"] == broken["error"]
    assert table["lamps.usda", "output=good"]["error"] == ""
    assert "failed: lamps.usda [output=broken]" in (out / "index.html").read_text()


def test_a_second_sweep_into_the_folder_is_refused_and_the_table_is_every_cases_record(
        tmp_path):
    """While a sweep writes into OUT, another is refused at once naming it (exit 2); once
    the first has ended, the second runs, and the table holds the cases both recorded."""
    import signal

    shutil.copy(REFERENCE / "isotropic.usda", tmp_path / "a.usda")  # quick
    shutil.copy(REFERENCE / "integrating_sphere.usda", tmp_path / "b.usda")  # long paths
    shutil.copy(REFERENCE / "lambertian_disc.usda", tmp_path / "c.usda")
    out = tmp_path / "out"
    base = [sys.executable, "-m", "lumitrace", "sweep", "--resolution", "8", "--threads",
            "1", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(ROOT / "service")}
    first = subprocess.Popen([*base, str(tmp_path / "a.usda"), str(tmp_path / "b.usda"),
                              "--photons", "4e7"], stderr=subprocess.PIPE, text=True,
                             cwd=ROOT, env=env)
    for line in first.stderr:  # a line per case: a is recorded, b is being traced
        if line.startswith("[1/2] a.usda"):
            break
    second = subprocess.run([*base, str(tmp_path / "c.usda"), "--photons", "20000"],
                            capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    still = first.poll() is None
    first.send_signal(signal.SIGINT)
    first.communicate(timeout=120)
    assert still, "the first sweep ended before the second started"
    assert second.returncode == 2, second.stderr
    assert f"another sweep is writing into this folder (pid {first.pid}," in second.stderr
    assert "lumitrace sweep" in second.stderr and "c.usda" not in os.listdir(out)
    again = subprocess.run([*base, str(tmp_path / "c.usda"), "--photons", "20000", "--json"],
                           capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    assert again.returncode == 0, again.stderr
    assert [os.path.basename(r["stage"]) for r in json.loads(
        again.stdout.splitlines()[-1])["rows"]] == ["c.usda"]
    with open(out / "sweep.csv") as f:
        assert sorted(os.path.basename(r["stage"]) for r in csv.DictReader(f)) == \
            ["a.usda", "c.usda"]
    assert not (out / ".lumitrace-sweep.lock").exists()
