"""The write path as one transaction, tried as it runs: the real CLI in subprocesses, real
signals at chosen moments of the write, concurrent runs, a stage edited while the result
layer is sublayered, crashes after the commit point, and bad options caught up front."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers.mounts import tmpfs
from helpers.paths import ROOT

DISC = ROOT / "stages" / "reference" / "lambertian_disc.usda"
OUTPUTS = (".intensity.exr", ".ies", ".ldt", ".polar.png", ".solid.png", ".lumitrace.usda")


def _cli(*args, **kw):
    return subprocess.Popen([sys.executable, "-m", "lumitrace.cli", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def _trace(stage, *extra, photons=60_000, seed=1):
    p = _cli("trace", stage, "--photons", photons, "--resolution", 16, "--seed", seed,
             "--no-progress", "--threads", 1, *extra)
    out, err = p.communicate(timeout=300)
    return p.returncode, out, err


def run_ids(folder: Path, name: str) -> dict[str, str | None]:
    from lumitrace.publish.runs import published_run_ids

    return published_run_ids(folder, name)


def assert_one_complete_set(folder: Path, name: str) -> str:
    ids = run_ids(folder, name)
    assert len(set(ids.values())) == 1 and None not in ids.values(), ids
    for suffix in OUTPUTS:
        assert (folder / f"{name}{suffix}").stat().st_size > 0
    leftovers = [p.name for p in folder.iterdir()
                 if p.name.startswith(f".{name}") and not p.name.endswith(".lock")]
    assert not leftovers, leftovers
    return ids["exr"]


@pytest.fixture
def disc(tmp_path):
    stage = tmp_path / "disc.usda"
    shutil.copy(DISC, stage)
    return stage


def test_a_run_publishes_one_set_with_one_run_id(disc):
    code, _, err = _trace(disc)
    assert code == 0, err
    assert_one_complete_set(disc.parent, "disc")


def test_signals_at_any_moment_leave_the_old_set_or_the_new_set(disc):
    """SIGTERM, SIGINT and SIGHUP sent at moments spread over a whole run (reading,
    tracing, the write window): every time the folder holds one complete set, and the
    message says truthfully which."""
    code, _, err = _trace(disc, seed=1)
    assert code == 0, err
    first = assert_one_complete_set(disc.parent, "disc")
    stage_bytes = disc.read_bytes()
    t0 = time.perf_counter()
    assert _trace(disc, seed=2)[0] == 0
    total = time.perf_counter() - t0
    seen = {"old": 0, "new": 0}
    sigs = [signal.SIGTERM, signal.SIGINT, signal.SIGHUP]
    for k, frac in enumerate((0.35, 0.55, 0.7, 0.8, 0.88, 0.94)):
        before = assert_one_complete_set(disc.parent, "disc")
        p = _cli("trace", disc, "--photons", 60_000, "--resolution", 16, "--seed", 10 + k,
                 "--no-progress", "--threads", 1)
        time.sleep(frac * total)
        p.send_signal(sigs[k % 3])
        _, err = p.communicate(timeout=120)
        after = assert_one_complete_set(disc.parent, "disc")
        if p.returncode in (0, -sigs[k % 3]):
            # the signal came after main() had returned: the run was complete
            assert after != before
            seen["new"] += 1
            continue
        assert p.returncode == 128 + sigs[k % 3], err
        said = [line for line in err.strip().splitlines() if not line.startswith("warning: ")]
        assert "Traceback" not in err and len(said) == 1, err  # (warnings printed before it)
        if after == before:
            assert "nothing was written" in err, err
            seen["old"] += 1
        else:
            assert "published" in err, err
            seen["new"] += 1
    assert first and sum(seen.values()) == 6
    # the stage only ever gained the one sublayer entry
    assert disc.read_bytes() == stage_bytes


def test_concurrent_runs_publish_one_after_the_other(disc):
    procs = [_cli("trace", disc, "--photons", 40_000, "--resolution", 16, "--seed", s,
                  "--no-progress", "--threads", 1) for s in (1, 2, 3)]
    results = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0], [r[1] for r in results]
    assert_one_complete_set(disc.parent, "disc")
    text = disc.read_text()
    assert text.count("disc.lumitrace.usda") == 1


def test_stale_staging_and_temporary_files_are_cleaned_up(disc):
    folder = disc.parent
    stale = folder / ".disc.lumitrace-staging-0123456789abcdef"
    stale.mkdir()
    (stale / "disc.ies").write_text("half")
    tmp = folder / ".disc.intensity.abcd1234.tmp.exr"
    tmp.write_bytes(b"half")
    code, _, err = _trace(disc)
    assert code == 0, err
    assert not stale.exists() and not tmp.exists()
    assert "removed the unfinished outputs" in err
    assert_one_complete_set(folder, "disc")


def test_a_crash_after_the_commit_point_is_rolled_forward(tmp_path, monkeypatch):
    from lumitrace.publish import transaction as tr

    targets = [tmp_path / "lamp.ies", tmp_path / "lamp.ldt"]
    for t in targets:
        t.write_text("old")
    tx = tr.Transaction("lamp", tmp_path)
    for t in targets:
        tx.staged(t).write_text("new")
    real = os.replace
    calls = []

    def crash_after_first(src, dst):
        calls.append(dst)
        if len(calls) == 3:  # the journal, the first file, then the crash
            raise SystemExit("killed")  # as if the process died mid-commit
        real(src, dst)

    monkeypatch.setattr(tr.os, "replace", crash_after_first)
    with pytest.raises(SystemExit):
        tx.commit()
    monkeypatch.setattr(tr.os, "replace", real)
    assert [t.read_text() for t in targets] == ["new", "old"]  # the mixed state a crash leaves
    done = tr.recover([tmp_path], "lamp")
    assert [t.read_text() for t in targets] == ["new", "new"]
    assert any("completed the interrupted publishing" in d for d in done)
    assert not list(tmp_path.glob(".lamp*journal*")) and not list(tmp_path.glob(".lamp.lumi*"))


def test_a_stage_saved_during_the_sublayer_edit_is_not_lost(disc, monkeypatch):
    """A DCC saves the stage between our read and our swap: the swap notices, starts
    again from the saved file, and both the DCC's edit and our sublayer entry are kept."""
    from lumitrace.publish import sublayer

    real = sublayer._edited_bytes
    saved = []

    def dcc_saves_meanwhile(stage, data, *args):
        out = real(stage, data, *args)
        if not saved:
            text = disc.read_text().replace("(\n", '(\n    doc = "edited by a DCC"\n', 1)
            disc.write_text(text)
            saved.append(True)
        return out

    monkeypatch.setattr(sublayer, "_edited_bytes", dcc_saves_meanwhile)
    layer = disc.with_name("disc.lumitrace.usda")
    layer.write_text("#usda 1.0\n")
    sublayer.sublayer_into_root(disc, layer)
    text = disc.read_text()
    assert 'doc = "edited by a DCC"' in text and "@./disc.lumitrace.usda@" in text
    assert saved


def test_the_stage_keeps_its_mode_and_hard_links(disc):
    link = disc.with_name("alias.usda")
    os.link(disc, link)
    os.chmod(disc, 0o640)
    ino = disc.stat().st_ino
    code, _, err = _trace(disc)
    assert code == 0, err
    assert disc.stat().st_ino == ino and disc.stat().st_nlink == 2
    assert (disc.stat().st_mode & 0o777) == 0o640
    assert "disc.lumitrace.usda" in link.read_text()


def test_two_stages_of_one_name_never_share_outputs(tmp_path):
    from pxr import Sdf

    a = tmp_path / "lamp.usda"
    shutil.copy(DISC, a)
    b = tmp_path / "lamp.usdc"
    Sdf.Layer.FindOrOpen(str(DISC)).Export(str(b))
    assert _trace(a)[0] == 0
    before = run_ids(tmp_path, "lamp")
    code, _, err = _trace(b)
    assert code == 2 and "another stage" in err and len(err.strip().splitlines()) == 1, err
    assert run_ids(tmp_path, "lamp") == before
    # with a folder of their own they are fine
    assert _trace(b, "--out", tmp_path / "usdc")[0] == 0  # the result layer goes there too
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(DISC, other / "lamp.usda")
    shared = tmp_path / "shared"
    assert _trace(other / "lamp.usda", "--out", shared)[0] == 0
    code, _, err = _trace(a, "--out", shared)
    assert code == 2 and "another stage" in err


@pytest.mark.parametrize("args, words", [
    (["--seed", str(2 ** 31)], "seed"),
    (["--photons", "inf"], "--photons"),
    (["--resolution", "100000"], "resolution"),
    (["--threshold", "nan"], "--threshold"),
])
def test_bad_options_are_one_line_before_anything_runs(disc, args, words):
    p = _cli("trace", disc, "--no-progress", *args)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 2 and words in err and "Traceback" not in err, err
    assert not disc.with_name("disc.intensity.exr").exists()


def test_an_output_folder_that_is_a_file_is_refused_before_tracing(disc):
    f = disc.with_name("not_a_folder")
    f.write_text("")
    t0 = time.perf_counter()
    code, _, err = _trace(disc, "--out", f, photons=50_000_000)
    assert code == 2 and "not a folder" in err and time.perf_counter() - t0 < 20
    assert len(err.strip().splitlines()) == 1


def test_a_fifo_as_the_stage_is_refused_not_waited_on(tmp_path):
    fifo = tmp_path / "stage.usda"
    os.mkfifo(fifo)
    code, _, err = _trace(fifo)
    assert code == 2 and "not a regular file" in err


def test_read_only_stage_folder_is_refused_before_tracing(disc):
    if os.geteuid() == 0:
        pytest.skip("root writes into read-only folders")
    os.chmod(disc.parent, 0o555)
    try:
        code, _, err = _trace(disc)
    finally:
        os.chmod(disc.parent, 0o755)
    assert code == 2 and "not writable" in err


def test_full_stdout_after_publishing_says_the_outputs_are_written(disc):
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full")
    with open("/dev/full", "w") as full:
        p = subprocess.run([sys.executable, "-m", "lumitrace.cli", "trace", str(disc),
                            "--photons", "40000", "--resolution", "16", "--no-progress",
                            "--json"], stdout=full, stderr=subprocess.PIPE, text=True,
                           timeout=300)
    assert p.returncode == 2 and "outputs were written" in p.stderr
    assert "Traceback" not in p.stderr
    assert_one_complete_set(disc.parent, "disc")


def test_summary_names_the_run_outputs(disc):
    code, out, err = _trace(disc, "--json")
    assert code == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    for key in ("intensity_map", "ies", "ldt", "result_layer"):
        assert Path(summary["outputs"][key]).exists()


@pytest.fixture
def small_disk(tmp_path):
    """A real 6 MiB tmpfs (needs root and mount; skipped with the reason otherwise)."""
    with tmpfs(tmp_path / "disk", "6m") as mount:
        yield mount


def test_a_full_disk_keeps_the_earlier_set_and_says_so(small_disk):
    stage = small_disk / "disc.usda"
    shutil.copy(DISC, stage)
    rc, _, err = _trace(stage, "--resolution", 32)
    assert rc == 0, err
    first = assert_one_complete_set(small_disk, "disc")
    stage_bytes = stage.read_bytes()
    # fill the disk, leaving less than one run's outputs
    free = shutil.disk_usage(small_disk).free
    with open(small_disk / "filler", "wb") as fh:
        fh.write(b"\0" * max(0, free - 64 * 1024))
    rc, out, err = _trace(stage, "--resolution", 32, seed=2)
    assert rc == 2, (out, err)
    lines = [ln for ln in err.splitlines() if ln.startswith("lumitrace")]
    assert len(lines) == 1 and "No space left on device" in lines[0], err
    assert "Traceback" not in err
    assert assert_one_complete_set(small_disk, "disc") == first  # the earlier set, whole
    assert stage.read_bytes() == stage_bytes
    assert not list(small_disk.glob(".disc.lumitrace-staging-*"))


@pytest.mark.parametrize("launcher", ["lumitrace", "python -m lumitrace"])
@pytest.mark.parametrize("delay", [0.05, 0.2, 0.4, 0.6])
def test_ctrl_c_while_lumitrace_loads_stops_the_run(disc, delay, launcher):
    """SIGINT in the first moments (Python and USD loading their modules, which can swallow
    a KeyboardInterrupt) stops the run before it traces: one line, status 130, no outputs,
    through the ``lumitrace`` entry point and through ``python -m lumitrace`` alike.
    (Enough photons that tracing still runs at the last delay: the outputs' write, once
    begun, is finished before a signal is taken.)"""
    # the delay counts from the interpreter being up (a signal during Python's own start-up,
    # before any of our code runs, is the interpreter's to handle)
    start = ("import lumitrace_launch; sys.exit(lumitrace_launch.main())"
             if launcher == "lumitrace" else "import runpy; sys.argv[0] = '-m'; "
             "runpy.run_module('lumitrace', run_name='__main__', alter_sys=True)")
    p = subprocess.Popen([sys.executable, "-c",
                          f"import sys; print('up', flush=True); {start}",
                          "trace", str(disc), "--photons", "40000000", "--no-progress"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert p.stdout.readline() == "up\n"
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=120)
    assert p.returncode == 130, (out, err)
    assert err.strip().splitlines() == [
        "lumitrace: SIGINT: interrupted; nothing was written, earlier outputs are unchanged"]
    assert sorted(q.name for q in disc.parent.iterdir() if not q.name.endswith(".lock")) == \
        ["disc.usda"]


def test_signals_held_holds_a_signal_another_thread_takes():
    """A signal the kernel hands to another thread (one started before the hold, as a
    library's worker threads are) still waits for the end of the held block."""
    import threading

    from lumitrace.publish.transaction import signals_held

    go, sent = threading.Event(), threading.Event()

    def send():
        go.wait()
        os.kill(os.getpid(), signal.SIGINT)
        sent.set()

    # Python's own SIGINT handler, whatever an earlier test in this process left there
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    helper = threading.Thread(target=send)
    helper.start()
    finished = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with signals_held():
                go.set()
                sent.wait()
                for _ in range(200):  # bytecode boundaries, where Python runs its handlers
                    time.sleep(0.001)
                finished.append(True)
    finally:
        signal.signal(signal.SIGINT, before)
    helper.join()
    assert finished == [True]


def test_a_signal_after_the_commit_says_the_outputs_are_published(disc, monkeypatch):
    """A signal landing after the set is committed (while the result layer is reloaded,
    before the stage is sublayered) leaves the new set, and the interruption says so."""
    import signal as sig

    from lumitrace.errors import Interrupted
    from lumitrace.publish import outputs
    from lumitrace.run.session import run
    from lumitrace.run.settings import TraceSettings
    from lumitrace.stage.reader import read_stage

    result = run(read_stage(disc), TraceSettings(photons=20_000, resolution=8, seed=3))

    def signalled(path):
        raise Interrupted(sig.SIGTERM)

    monkeypatch.setattr(outputs, "reload_if_open", signalled)
    with pytest.raises(Interrupted) as stop:
        outputs.write_outputs(result, disc.parent, sublayer=False)
    assert stop.value.published
    assert_one_complete_set(disc.parent, "disc")
