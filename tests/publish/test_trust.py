"""Nothing lost, nothing overwritten, nothing trusted that lumitrace did not write: the write
path tried as an attacker and as a careless user would, with the real command line."""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.paths import ROOT

DISC = ROOT / "stages" / "reference" / "lambertian_disc.usda"


def lumitrace(*args, **kw):
    p = subprocess.run([sys.executable, "-m", "lumitrace", *map(str, args)],
                       capture_output=True, text=True, timeout=300, **kw)
    return p.returncode, p.stdout, p.stderr


def trace(stage, *extra, photons=40_000):
    return lumitrace("trace", stage, "--photons", photons, "--resolution", 16,
                     "--no-progress", "--threads", 1, "--no-pictures", *extra)


@pytest.fixture
def dl(tmp_path):
    stage = tmp_path / "dl.usda"
    shutil.copy(DISC, stage)
    return stage


def error_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("lumitrace: error")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# -- 1. a forged journal -----------------------------------------------------------------

def test_a_forged_journal_cannot_replace_a_file_outside_the_outputs(dl, tmp_path):
    victim = tmp_path / "home" / "victim.txt"
    victim.parent.mkdir()
    victim.write_text("precious")
    assert trace(dl)[0] == 0
    journal = dl.with_name(".dl.lumitrace-journal")
    journal.write_text(json.dumps({"run": "evil", "moves": [[str(dl.with_name("dl.ldt")),
                                                             str(victim)]]}))
    code, _, err = trace(dl)
    assert code == 0, err
    assert victim.read_text() == "precious"
    assert "completed the interrupted publishing" not in err
    assert "did not write" in err
    assert dl.with_name("dl.ldt").exists()


def test_a_signed_journal_still_moves_only_staged_outputs(tmp_path):
    """Even a journal with a valid signature (the key stolen, or a bug) may only rename a
    file out of this stage's staging folder onto an output name beside it."""
    from lumitrace.publish import transaction as tr

    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "out"
    out.mkdir()
    staging = out / ".dl.lumitrace-staging-0123456789abcdef"
    staging.mkdir()
    (staging / "victim.txt").write_text("evil")
    (staging / "dl.ies").write_text("evil")
    for moves in ([[str(staging / "victim.txt"), str(victim)]],
                  [[str(staging / "dl.ies"), str(out / "dl.usda")]],
                  [[str(out / "dl.ldt"), str(out / "dl.ies")]]):
        record = tr.sign({"run": "0123456789abcdef", "name": "dl", "moves": moves})
        (out / ".dl.lumitrace-journal").write_text(json.dumps(record))
        done = tr.recover([out], "dl")
        assert any("does not write" in d for d in done), done
        assert victim.read_text() == "precious" and not (out / "dl.usda").exists()
        staging.mkdir(exist_ok=True)
        (staging / "victim.txt").write_text("evil")


def test_a_journal_of_another_user_is_not_signed_by_ours(tmp_path, monkeypatch):
    from lumitrace.publish import transaction as tr

    record = tr.sign({"run": "0123456789abcdef", "name": "dl", "moves": []})
    assert tr._signed_by_us(record)
    monkeypatch.setattr(tr, "_KEY", [os.urandom(32)])  # another user's key
    assert not tr._signed_by_us(record)
    assert not tr._signed_by_us({k: v for k, v in record.items() if k != "mac"})


# -- 2. user files named like outputs ----------------------------------------------------

def test_a_user_file_named_like_the_result_layer_is_refused_before_tracing(dl):
    mine = dl.with_name("dl.lumitrace.usda")
    mine.write_text("#usda 1.0\n# my own stage, not a result\n")
    code, _, err = trace(dl, photons=50_000_000)  # refused before the long trace
    assert code == 2 and "dl.lumitrace.usda" in error_line(err)
    assert mine.read_text() == "#usda 1.0\n# my own stage, not a result\n"
    assert not dl.with_name("dl.ies").exists()


def test_a_measured_profile_the_stage_reads_is_never_replaced(tmp_path):
    from pxr import Usd, UsdLux

    profile = ROOT / "tests" / "data" / "photometry"
    ies = next(profile.glob("*.ies"))
    lamp = tmp_path / "lamp.usda"
    shutil.copy(ies, tmp_path / "lamp.ies")
    original = (tmp_path / "lamp.ies").read_bytes()
    stage = Usd.Stage.CreateNew(str(lamp))
    stage.SetMetadata("metersPerUnit", 1.0)
    stage.SetMetadata("upAxis", "Z")
    root = stage.DefinePrim("/Luminaire", "Xform")
    stage.SetDefaultPrim(root)
    light = UsdLux.DiskLight.Define(stage, "/Luminaire/Led")
    light.CreateRadiusAttr(0.01)
    light.GetPrim().CreateAttribute("lumitrace:luminousFlux",
                                    __import__("pxr").Sdf.ValueTypeNames.Float).Set(1000.0)
    shaping = UsdLux.ShapingAPI.Apply(light.GetPrim())
    shaping.CreateShapingIesFileAttr("./lamp.ies")
    stage.Save()
    code, _, err = trace(lamp)
    assert code == 2 and "lamp.ies" in error_line(err) and "reads" in err
    assert (tmp_path / "lamp.ies").read_bytes() == original
    # an edited output of ours is not ours any more either
    assert trace(lamp, "--out", tmp_path / "out")[0] == 0
    ldt = tmp_path / "out" / "lamp.ldt"
    ldt.write_text(ldt.read_text() + "\n")
    code, _, err = trace(lamp, "--out", tmp_path / "out")
    assert code == 2 and "changed since lumitrace wrote it" in err


# -- 3. rays over the stage -----------------------------------------------------------------

def test_rays_never_replace_the_stage_or_a_foreign_file(dl):
    before = dl.read_bytes()
    code, _, err = lumitrace("rays", dl, "--out", dl, "--photons", 1000)
    assert code == 2 and "reads" in error_line(err) and dl.read_bytes() == before
    foreign = dl.with_name("notes.TM25RAY")
    foreign.write_text("not rays")
    code, _, err = lumitrace("rays", dl, "--out", foreign, "--photons", 1000)
    assert code == 2 and foreign.read_text() == "not rays"
    assert lumitrace("rays", dl, "--photons", 1000)[0] == 0
    assert lumitrace("rays", dl, "--photons", 2000)[0] == 0  # our own file: replaced


# -- 4. the compare-and-swap window --------------------------------------------------------

def test_a_save_landing_between_the_compare_and_the_swap_is_kept(dl, monkeypatch):
    """A DCC saves the stage at the last instant, after our compare, before our file goes
    in: the save must survive, with our sublayer entry added on top of it."""
    from lumitrace.publish import sublayer

    real_replace = os.replace
    saved = []

    def dcc_save():
        if not saved:
            saved.append(True)
            tmp = dl.with_name("dcc-save.tmp")
            tmp.write_text(dl.read_text().replace("(\n", '(\n    doc = "saved by a DCC"\n', 1))
            real_replace(tmp, dl)

    def replace(src, dst):
        if Path(dst) == dl:
            dcc_save()
        return real_replace(src, dst)

    monkeypatch.setattr(sublayer.os, "replace", replace)
    real_exchange = getattr(sublayer, "_exchange", None)
    if real_exchange is not None:
        def exchange(a, b):
            if Path(b) == dl:
                dcc_save()
            return real_exchange(a, b)
        monkeypatch.setattr(sublayer, "_exchange", exchange)
    layer = dl.with_name("dl.lumitrace.usda")
    layer.write_text("#usda 1.0\n")
    sublayer.sublayer_into_root(dl, layer)
    text = dl.read_text()
    assert saved and 'doc = "saved by a DCC"' in text, text[:400]
    assert "@./dl.lumitrace.usda@" in text


def _outputs(stage: Path) -> dict[str, bytes]:
    """The bytes of every output of the stage's last run (the stage itself left out)."""
    return {p.name: p.read_bytes() for p in stage.parent.iterdir()
            if p.is_file() and p.name.startswith("dl.") and p.name != stage.name}


@pytest.mark.parametrize("committed", [True, False])
def test_a_run_beside_another_runs_commit_waits_for_it_and_a_foreign_edit_is_refused(
        dl, committed):
    """Another run of the stage holds the publishing lock and has replaced the map but not
    yet its record: a run starting then waits for the lock rather than refusing (the
    commit ends in a whole set, which it then takes over); where the holder leaves the map
    changed (an edit, not a commit), it is refused as before, nothing replaced."""
    import threading
    import time

    from lumitrace.publish.transaction import locked

    assert trace(dl)[0] == 0
    first = _outputs(dl)
    assert trace(dl)[0] == 0
    exr = dl.with_name("dl.intensity.exr")
    assert exr.read_bytes() != first[exr.name]
    held, release = threading.Event(), threading.Event()

    def commit():
        with locked([dl.parent], "dl"):
            exr.write_bytes(first[exr.name])  # the map replaced, the record not yet
            held.set()
            release.wait(30)
            if committed:  # the commit's end: the whole earlier set, record and all
                for name, data in first.items():
                    dl.with_name(name).write_bytes(data)

    holder = threading.Thread(target=commit)
    holder.start()
    assert held.wait(30)
    run = subprocess.Popen([sys.executable, "-m", "lumitrace", "trace", str(dl), "--photons",
                            "40000", "--resolution", "16", "--no-progress", "--threads", "1",
                            "--no-pictures"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    time.sleep(3.0)  # the run reads the stage and finds the map changed meanwhile
    assert run.poll() is None  # waiting for the lock, not refused
    release.set()
    holder.join()
    left = _outputs(dl)
    _, err = run.communicate(timeout=300)
    if committed:
        assert run.returncode == 0, err
        assert exr.read_bytes() != first[exr.name]  # its own map now
    else:
        assert run.returncode == 2 and "changed since lumitrace wrote it" in error_line(err)
        assert _outputs(dl) == left  # nothing replaced


# -- 5. moved and copied folders ---------------------------------------------------------

def test_a_moved_folder_retraces_in_place_and_a_copy_as_its_own_stage(tmp_path):
    v1 = tmp_path / "v001"
    v1.mkdir()
    shutil.copy(DISC, v1 / "dl.usda")
    assert trace(v1 / "dl.usda")[0] == 0
    v2 = tmp_path / "v002"
    shutil.move(v1, v2)
    code, _, err = trace(v2 / "dl.usda")
    assert code == 0, err
    v3 = tmp_path / "v003"
    shutil.copytree(v2, v3)
    code, _, err = trace(v3 / "dl.usda")
    assert code == 0, err
    for v in (v2, v3):
        assert lumitrace("check", v / "dl.usda")[0] in (0, 3)
        assert (v / "dl.usda").read_text().count("lumitrace.usda@") == 1


def test_a_moved_stage_takes_over_its_out_folder_and_a_live_one_is_refused(tmp_path):
    a = tmp_path / "a"
    a.mkdir()
    shutil.copy(DISC, a / "dl.usda")
    out = tmp_path / "results"
    assert trace(a / "dl.usda", "--out", out)[0] == 0
    b = tmp_path / "b"
    shutil.copytree(a, b)
    code, _, err = trace(b / "dl.usda", "--out", out)  # a still lives: not shared
    assert code == 2 and "another stage" in err
    shutil.rmtree(a)
    code, _, err = trace(b / "dl.usda", "--out", out)  # a is gone: b takes over
    assert code == 0 and "took over" in err, err
    assert (b / "dl.usda").read_text().count("lumitrace.usda@") == 1


# -- 6. several --out folders --------------------------------------------------------------

def test_the_newest_out_folder_is_the_one_result_the_stage_composes(dl):
    for folder in ("A", "B"):
        assert trace(dl, "--out", dl.parent / folder)[0] == 0
    text = dl.read_text().replace("float lumitrace:luminousFlux = 1000",
                                  "float lumitrace:luminousFlux = 1200")
    assert "1200" in text
    dl.write_text(text)
    assert trace(dl, "--out", dl.parent / "A")[0] == 0
    code, out, err = lumitrace("check", dl, "--json")
    assert json.loads(out)["status"] in ("current", "not converged"), out
    assert "./B/" not in dl.read_text() and dl.read_text().count("lumitrace.usda@") == 1


# -- 7. pictures of an earlier run ---------------------------------------------------------

def test_no_pictures_removes_the_previous_runs_pictures(dl):
    code, _, err = lumitrace("trace", dl, "--photons", 40_000, "--resolution", 16,
                             "--no-progress", "--threads", 1)
    assert code == 0, err
    assert dl.with_name("dl.polar.png").exists()
    assert trace(dl)[0] == 0
    assert not dl.with_name("dl.polar.png").exists()
    assert not dl.with_name("dl.solid.png").exists()


# -- 8. check for --out --no-sublayer results ----------------------------------------------

def test_check_gates_results_written_to_an_out_folder_without_sublayering(dl):
    out = dl.parent / "results"
    assert trace(dl, "--out", out, "--no-sublayer", "--target-error", "0.5")[0] == 0
    code, stdout, _ = lumitrace("check", dl, "--out", out, "--json")
    assert code == 0 and json.loads(stdout)["status"] == "current", stdout
    assert lumitrace("check", dl)[0] == 1  # not in the stage's own composition
    dl.write_text(dl.read_text().replace("float lumitrace:luminousFlux = 1000",
                                         "float lumitrace:luminousFlux = 900"))
    code, stdout, _ = lumitrace("check", dl, "--out", out, "--json")
    assert code == 1 and json.loads(stdout)["status"] == "stale"


def test_check_refuses_a_fifo_at_once(tmp_path):
    fifo = tmp_path / "stage.usda"
    os.mkfifo(fifo)
    code, _, err = lumitrace("check", fifo)
    assert code == 2 and "not a regular file" in err
