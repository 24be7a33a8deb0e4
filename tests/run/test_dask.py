"""Batches on a real Dask cluster (a scheduler and two worker processes on loopback): the
same counts as a local run, a worker killed mid-run costs nothing but redone batches, a
scheduler that goes away ends the run with the batches that finished written, and a worker
with another lumitrace is refused."""
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from helpers.paths import ROOT, STAGES
from helpers.tallies import same_tally

distributed = pytest.importorskip("distributed")
SchedulerPlugin = pytest.importorskip("distributed.diagnostics.plugin").SchedulerPlugin

SMALL = dict(resolution=16, batch_size=1 << 14, threads=2, seed=5)


@pytest.fixture(scope="module")
def cluster():
    """A scheduler and two single-threaded worker processes on loopback, and a client."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=":0") as c, \
            distributed.Client(c, set_as_default=False) as client:
        client.wait_for_workers(2, timeout=60)
        yield c.scheduler_address, client


def _scene(name):
    from lumitrace.stage.reader import read_stage

    return read_stage(STAGES / name)


def _same_accumulators(a, b):
    assert a.accumulator.photons == b.accumulator.photons
    assert len(a.accumulator.emitters) == len(b.accumulator.emitters)
    for i, (x, y) in enumerate(zip(a.accumulator.emitters, b.accumulator.emitters)):
        same_tally(x, y, f"emitter {i}")


@pytest.mark.parametrize("stage, photons", [
    ("downlight.usda", 200_000),  # plain
    ("warm_downlight.usda", 100_000),  # spectral: X and Z tallies too
    ("louvre.usda", 100_000),  # 32 emitters: many small jobs a round
])
def test_counts_on_the_cluster_equal_the_local_run(cluster, stage, photons):
    from lumitrace.run.session import run
    from lumitrace.run.settings import TraceSettings

    address, _ = cluster
    scene = _scene(stage)
    local = run(scene, TraceSettings(photons=photons, **SMALL))
    remote = run(scene, TraceSettings(photons=photons, scheduler=address, **SMALL))
    _same_accumulators(local, remote)
    assert remote.accumulator.emitters[0].cells is not None  # goniometer counts compared
    if stage.startswith("warm"):
        assert remote.accumulator.emitters[0].xz is not None
    assert remote.batches_redone == 0


def test_the_command_writes_the_same_files_as_a_local_run(cluster, tmp_path):
    """`lumitrace trace --scheduler` writes maps and photometric files identical to a local
    trace (same seed and photons); its --json says no batch was redone."""
    import OpenImageIO as oiio

    address, _ = cluster
    outs = {}
    for name, extra in (("local", []), ("dask", ["--scheduler", address])):
        out = tmp_path / name
        r = subprocess.run([sys.executable, "-m", "lumitrace", "trace",
                            str(STAGES / "downlight.usda"), "--photons", "150000",
                            "--resolution", "16", "--batch-size", "16384", "--out", str(out),
                            "--no-sublayer", "--no-pictures", "--json", *extra],
                           capture_output=True, text=True, cwd=ROOT, timeout=120,
                           env={**os.environ, "PYTHONPATH": str(ROOT / "service")})
        assert r.returncode == 0, r.stderr
        outs[name] = out, json.loads(r.stdout.splitlines()[-1])
    (a, ja), (b, jb) = outs["local"], outs["dask"]
    assert ja["photons"] == jb["photons"] == 150_000 and jb["batches_redone"] == 0
    for suffix in (".ies", ".ldt"):  # the same bytes, but for each run's own id
        ta, tb = ((d / f"downlight{suffix}").read_bytes() for d in (a, b))
        assert ta != tb and ta.replace(run_id(ta), b"") == tb.replace(run_id(tb), b"")
    pa, pb = (oiio.ImageBuf(str(d / "downlight.intensity.exr")) for d in (a, b))
    assert np.array_equal(pa.get_pixels(oiio.FLOAT), pb.get_pixels(oiio.FLOAT))


def run_id(text: bytes) -> bytes:
    """The run id a photometric file names (``[_LUMITRACE_RUN] ID``, EULUMDAT's ``run ID``)."""
    return re.search(rb"run\]? ([0-9a-f]{16})", text, re.IGNORECASE).group(1)


def test_a_worker_killed_mid_run_changes_nothing_but_redone_batches(cluster):
    """SIGKILL to one worker while a round's batches run on it: the scheduler runs them
    again elsewhere, the counts are still the local run's, and the run says how many."""
    from lumitrace.run.session import run
    from lumitrace.run.settings import TraceSettings

    address, client = cluster
    scene = _scene("downlight.usda")
    settings = dict(photons=1_200_000, resolution=16, batch_size=1 << 15, threads=2, seed=9)
    local = run(scene, TraceSettings(**settings))
    pids = client.run(os.getpid)
    victim = sorted(pids)[0]
    killed = threading.Event()

    def kill_when_busy():
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            if client.processing(workers=[victim]).get(victim):
                os.kill(pids[victim], signal.SIGKILL)
                killed.set()
                return
            time.sleep(0.002)

    def progress(p):
        if p.iteration == 2:  # the next round is submitted as soon as this returns
            threading.Thread(target=kill_when_busy, daemon=True).start()

    with pytest.warns(UserWarning, match=r"^\d+ batch\(es\) sent again after a Dask "
                                         r"worker was lost \(the result is the same\)$"):
        remote = run(scene, TraceSettings(scheduler=address, **settings), progress=progress)
    assert killed.is_set()
    _same_accumulators(local, remote)
    assert remote.batches_redone >= 1
    client.wait_for_workers(2, timeout=60)  # the nanny starts a new worker


def test_a_worker_with_another_lumitrace_is_refused(cluster, monkeypatch):
    import lumitrace
    from lumitrace.errors import LumitraceError
    from lumitrace.run import cluster as dask_pool
    from lumitrace.run.session import run
    from lumitrace.run.settings import TraceSettings
    from lumitrace.trace.job import BatchJob
    from lumitrace.trace.prepared import TracingFrame

    address, _ = cluster
    scene = _scene("downlight.usda")
    runner = dask_pool.cluster_runner(address, scene, TracingFrame.of(scene))
    try:  # a worker that joined after the check: its batches fail, and the run says why
        runner.expected = ("0.0.0", "000000000000")
        with pytest.raises(LumitraceError, match=r"joined during the run \(tcp://127\.0\.0\.1:"
                                                 rf"\d+\) runs lumitrace {lumitrace.__version__}"):
            list(runner([BatchJob(0, 0, 100, 0, 8)]))
    finally:
        runner.close()
    monkeypatch.setattr(lumitrace, "__version__", "0.0.1+other")
    with pytest.raises(LumitraceError, match=r"Dask worker tcp://127\.0\.0\.1:\d+( \(and 1 "
                                             r"more\))? runs lumitrace 0\.1\.0 .*this run "
                                             r"0\.0\.1\+other"):
        run(scene, TraceSettings(photons=10_000, scheduler=address, **SMALL))


def test_no_scheduler_is_one_clear_error():
    from lumitrace.errors import LumitraceError
    from lumitrace.run.cluster import connect

    with pytest.raises(LumitraceError, match="cannot reach the Dask scheduler"):
        connect("tcp://127.0.0.1:9", timeout=1)


def _start(args, log):
    return subprocess.Popen([sys.executable, "-m", *args], stdout=log, stderr=subprocess.STDOUT,
                            cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT / "service")})


def test_a_scheduler_that_goes_away_ends_the_run_with_the_finished_batches(tmp_path):
    """The scheduler killed mid-run: exit status 4, one line naming it, and the outputs of
    the batches that finished written (fewer photons than asked, a complete result)."""
    file = tmp_path / "scheduler.json"
    with open(tmp_path / "cluster.log", "w") as log:
        sched = _start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                        "--no-dashboard", "--scheduler-file", str(file)], log)
        worker = None
        try:
            for _ in range(300):
                if file.exists() and file.stat().st_size:
                    break
                time.sleep(0.1)
            address = json.loads(file.read_text())["address"]
            worker = _start(["distributed.cli.dask_worker", address, "--nthreads", "1",
                             "--no-dashboard", "--no-nanny"], log)
            out = tmp_path / "out"
            trace = subprocess.Popen(
                [sys.executable, "-m", "lumitrace", "trace", str(STAGES / "downlight.usda"),
                 "--photons", "50000000", "--resolution", "16", "--batch-size", "32768",
                 "--scheduler", address, "--out", str(out), "--no-sublayer", "--no-pictures",
                 "--threads", "1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT / "service")})
            for line in trace.stderr:  # one line per iteration (stderr is no terminal)
                if line.startswith("iteration 4:"):
                    break
            sched.kill()
            _, err = trace.communicate(timeout=120)
        finally:
            for p in (worker, sched):
                if p is not None and p.poll() is None:
                    p.kill()
                    p.wait()
    assert trace.returncode == 4, err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"lumitrace: error: {address}: the Dask scheduler went away "
                           "mid-run after "), last
    assert last.endswith("photons: the outputs hold the batches that finished")
    photons = int(last.split(" after ")[1].split()[0].replace(",", ""))
    assert 0 < photons < 50_000_000 and photons % 32768 == 0
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(str(out / "downlight.lumitrace.usda"))
    assert layer.GetAttributeAtPath("/Luminaire.lumitrace:result:photons").default == photons


def test_a_target_error_stops_the_run_on_the_cluster(cluster):
    from lumitrace.run.session import MIN_PHOTONS_FOR_FILES_TARGET, run
    from lumitrace.run.settings import TraceSettings

    address, _ = cluster
    seen = []
    r = run(_scene("downlight.usda"), TraceSettings(target_error=0.05, scheduler=address,
                                                    **SMALL), progress=seen.append)
    assert r.files_accuracy.meets(0.05)  # judged on the files, the default
    assert MIN_PHOTONS_FOR_FILES_TARGET <= r.photons < 4_000_000
    assert [p.photons for p in seen] == sorted({p.photons for p in seen})  # every round shown
    assert seen[-1].photons == r.photons and len(seen) == r.iterations


@pytest.mark.parametrize("stage, photons", [("warm_downlight.usda", 1 << 15),
                                            ("louvre.usda", 300)])
def test_a_tally_packed_for_the_network_unpacks_bit_for_bit(stage, photons):
    """Counts go over the network in the narrowest exact integer type, deflated: a dense
    spectral tally and a sparse one of few photons come back identical, and smaller."""
    import pickle

    from lumitrace.film.accumulate import SparseCounts
    from lumitrace.run.cluster import pack, unpack
    from lumitrace.run.workers import _traced
    from lumitrace.trace.job import BatchJob
    from lumitrace.trace.prepared import prepare

    emitter = 3 if stage.startswith("louvre") else 0
    tally = _traced(prepare(_scene(stage)), BatchJob(emitter, 1000, photons, 2, 32))
    wire = pack(tally)
    back = unpack(wire)
    same_tally(tally, back)
    assert isinstance(back.cells, type(tally.cells))
    if stage.startswith("louvre"):
        assert isinstance(tally.counts, SparseCounts)
    else:
        assert tally.xz is not None
    assert len(wire) * 3 < len(pickle.dumps(tally, protocol=5))


def test_a_sweep_on_the_cluster_equals_the_local_sweep(cluster, tmp_path):
    """Both variants of a variant set swept on the cluster: the same photometric grids as
    the local sweep's, and a rerun on the cluster traces nothing."""
    import shutil

    from lumitrace.report.sweep import plan, run_sweep, stage_files
    from lumitrace.run.settings import TraceSettings
    from pxr import Sdf, Usd

    address, _ = cluster
    stage = tmp_path / "disc.usda"
    shutil.copy(ROOT / "stages" / "reference" / "lambertian_disc.usda", stage)
    s = Usd.Stage.Open(str(stage))
    vs = s.GetDefaultPrim().GetVariantSets().AddVariantSet("output")
    for name, flux in (("low", 500.0), ("high", 2000.0)):
        vs.AddVariant(name)
        vs.SetVariantSelection(name)
        with vs.GetVariantEditContext():
            s.GetPrimAtPath("/Luminaire/Source").CreateAttribute(
                "lumitrace:luminousFlux", Sdf.ValueTypeNames.Float).Set(flux)
    s.GetPrimAtPath("/Luminaire/Source").GetAttribute("lumitrace:luminousFlux").Clear()
    s.GetRootLayer().Save()
    grids = {}
    for where, scheduler in (("local", None), ("dask", address)):
        out = tmp_path / where
        settings = TraceSettings(photons=30_000, scheduler=scheduler, **SMALL)
        cases = plan(stage_files([str(stage)]), None, out)
        rows = run_sweep(cases, settings, out)
        assert [r["variant"] for r in rows] == ["output=high", "output=low"]  # USD's order
        grids[where] = [json.loads(open(r["photometry_data"]).read())["candela"]
                        for r in rows]
        if scheduler:
            assert not any(r["traced"] for r in run_sweep(cases, settings, out))
    assert grids["local"] == grids["dask"]
    assert grids["dask"][0][0][0] == pytest.approx(4 * grids["dask"][1][0][0])  # the same
    # photons, four times the flux


def test_the_service_on_the_cluster_after_a_delta_equals_a_fresh_trace(cluster, tmp_path):
    """`lumitrace serve --scheduler`: its counts after a delta equal, exactly, those of a
    local `lumitrace trace --edits` of the stage and its edits layer in the same frame."""
    import shutil

    from lumitrace.publish.exr import read_intensity_exr
    from service_process import Service

    address, client = cluster
    stage = tmp_path / "downlight.usda"
    shutil.copy(STAGES / "downlight.usda", stage)
    args = ("--photons", 40_000, "--resolution", 16, "--seed", 5)
    client.register_plugin(_BatchCount())
    with Service(stage, *args, "--threads", 2, "--scheduler", address) as s:
        s.wait_done(0)
        s.client.set("/Luminaire/Materials/ReflectorAluminium",
                     "lumitrace:specularReflectance", 0.6)
        status = s.wait_done(1)
        served = read_intensity_exr(stage.parent / "downlight.intensity.exr")[0]["count"]
        assert s.stop()[0] == 0
    assert client.run_on_scheduler(_batches_sent) >= 4  # both revisions' rounds
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    shutil.copy(STAGES / "downlight.usda", fresh / "downlight.usda")
    shutil.copy(tmp_path / "downlight.lumitrace-edits.usda", fresh / "edits.usda")
    frame = ",".join(repr(v) for v in status["tracing_frame"])
    p = subprocess.run([sys.executable, "-m", "lumitrace", "trace", str(fresh / "downlight.usda"),
                        "--edits", str(fresh / "edits.usda"), *map(str, args), "--threads", "1",
                        "--no-progress", "--no-pictures", "--frame", frame], cwd=ROOT,
                       capture_output=True, text=True, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT / "service")})
    assert p.returncode == 0, p.stderr
    traced = read_intensity_exr(fresh / "downlight.intensity.exr")[0]["count"]
    assert served.sum() > 10_000
    np.testing.assert_array_equal(served, traced)


class _BatchCount(SchedulerPlugin):
    """Batches the scheduler sends to a worker from the plugin's registration on (its
    transition log keeps only the module's last 1000 transitions)."""

    name = "lumitrace-batch-count"

    def __init__(self):
        self.sent = 0

    def transition(self, key, start, finish, *args, **kwargs):
        if finish == "processing" and str(key).startswith("lumitrace-batch"):
            self.sent += 1


def _batches_sent(dask_scheduler) -> int:
    return dask_scheduler.plugins[_BatchCount.name].sent


def test_the_scene_lost_with_its_last_worker_is_sent_again(cluster):
    """The scheduler keeps one copy of scattered data: the worker holding the scene killed
    between rounds loses it; the next round sends it again and its counts are unchanged."""
    from lumitrace.run.cluster import cluster_runner
    from lumitrace.run.workers import _traced
    from lumitrace.trace.job import BatchJob
    from lumitrace.trace.prepared import TracingFrame, prepare

    address, client = cluster
    client.wait_for_workers(2, timeout=60)
    scene = _scene("downlight.usda")
    frame = TracingFrame.of(scene)
    jobs = [BatchJob(0, i * 5000, 5000, 1, 16) for i in range(6)]
    runner = cluster_runner(address, scene, frame)
    try:
        deadline = time.monotonic() + 30
        while len(holders := client.who_has(runner.scene[0])[runner.scene[0].key]) != 1:
            assert time.monotonic() < deadline, holders  # one copy is kept, in time
            time.sleep(0.1)
        os.kill(client.run(os.getpid)[holders[0]], signal.SIGKILL)
        while holders[0] in client.scheduler_info(n_workers=-1)["workers"]:
            time.sleep(0.05)
        tallies = list(runner(jobs))
        assert runner.redone >= len(jobs)  # every batch of the round sent again
    finally:
        runner.close()
    ps = prepare(scene, frame)
    for job, tally in zip(jobs, tallies):
        same_tally(_traced(ps, job), tally, f"job {job.first}")
    client.wait_for_workers(2, timeout=60)


def test_dask_is_loaded_only_when_a_scheduler_is_named():
    code = ("import sys\n"
            "from lumitrace.cli import build_parser\n"
            "from lumitrace.run.session import run\n"
            "from lumitrace.run.settings import TraceSettings\n"
            "from lumitrace.stage.reader import read_stage\n"
            "import lumitrace.serve.engine, lumitrace.report.sweep\n"
            "build_parser()\n"
            f"run(read_stage({str(STAGES / 'downlight.usda')!r}), TraceSettings(photons=2000,"
            " resolution=8, threads=1))\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', "
            "'distributed')))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(ROOT / "service")})
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stderr
