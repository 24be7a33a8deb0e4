"""A read stage's scene kept on disk (lumitrace.stage.scene_cache): taken again only while
every file it was read from holds the same bytes, and then without loading USD."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import lumitrace  # noqa: F401  (registers the schema before any stage is composed)
from lumitrace.photometry.distribution import CGammaGrid
from lumitrace.photometry.lm63 import format_ies
from lumitrace.stage import reader, scene_cache

FLUX = 1000.0

ROOT = """#usda 1.0
(
    defaultPrim = "Luminaire"
    metersPerUnit = 0.01
    upAxis = "Z"
    subLayers = [@./parts.usda@]
)

def Xform "Luminaire"
{
    def DiskLight "Led" (
        prepend apiSchemas = ["LumitraceEmitterAPI", "ShapingAPI"]
    )
    {
        float inputs:radius = 2
        float lumitrace:luminousFlux = FLUX
        asset inputs:shaping:ies:file = @./led.ies@
        bool inputs:shaping:ies:normalize = 1
    }

    def Xform "Cup" (
        prepend references = @./cup.usda@</Cup>
    )
    {
    }
}
"""
PARTS = """#usda 1.0

over "Luminaire"
{
    def Mesh "Lid"
    {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(-9, -9, 20), (9, -9, 20), (9, 9, 20), (-9, 9, 20)]
    }
}
"""
CUP = """#usda 1.0

def Xform "Cup"
{
    def Mesh "Wall"
    {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(-5, -5, -10), (5, -5, -10), (5, 5, -10), (-5, 5, -10)]
    }
}
"""


def _ies(path: Path, peak: float = 300.0) -> None:
    g = np.arange(0.0, 180.5, 5.0)
    cd = peak * np.maximum(np.cos(np.radians(g)), 0.0)[None, :]
    path.write_text(format_ies(CGammaGrid(np.array([0.0]), g, cd, "rotational"), FLUX,
                               0.0, 0.0, 0.0, {}))


def _settle(folder: Path, seconds: float = 60.0) -> None:
    """Every file of ``folder`` last modified ``seconds`` ago (a stage saved before the
    run, not while it reads)."""
    when = time.time() - seconds
    for f in folder.iterdir():
        os.utime(f, (when, when))


@pytest.fixture
def stage(tmp_path, monkeypatch):
    """A luminaire of four files: root layer, sublayer, referenced layer, IES profile;
    the cache in a folder of its own; reads by USD counted."""
    folder = tmp_path / "lum"
    folder.mkdir()
    (folder / "root.usda").write_text(ROOT.replace("FLUX", f"{FLUX:g}"))
    (folder / "parts.usda").write_text(PARTS)
    (folder / "cup.usda").write_text(CUP)
    _ies(folder / "led.ies")
    _settle(folder)
    monkeypatch.setenv("LUMITRACE_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(scene_cache.SEARCH_PATH_VARIABLE, raising=False)
    reads = []
    real = reader.read_stage_file

    def counted(*args, **kwargs):
        reads.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(reader, "read_stage_file", counted)
    return folder / "root.usda", reads


def _same_scene(a, b) -> None:
    assert a.content_hash() == b.content_hash()
    assert np.array_equal(a.triangles, b.triangles) and a.parts == b.parts
    assert (a.warnings, a.layer_files, a.time_code, a.info) == \
        (b.warnings, b.layer_files, b.time_code, b.info)
    assert [e.ies for e in a.emitters] == [e.ies for e in b.emitters]


def test_an_unchanged_stage_is_read_once(stage):
    path, reads = stage
    first = scene_cache.read_stage(path)
    assert len(first.input_files()) == 4  # three layers and the profile
    for _ in range(2):
        _same_scene(scene_cache.read_stage(path), first)
    assert len(reads) == 1


@pytest.mark.parametrize("name, old, new", [
    ("root.usda", "inputs:radius = 2", "inputs:radius = 3"),
    ("parts.usda", "(9, 9, 20)", "(8, 9, 20)"),
    ("cup.usda", "(5, 5, -10)", "(5, 4, -10)"),
])
def test_a_changed_layer_is_read_again_even_at_the_same_size_and_time(stage, name, old,
                                                                      new):
    """Content is what counts: an edit of the same length with the file's time put back
    (a copy that keeps times, a clock step) is seen."""
    path, reads = stage
    before = scene_cache.read_stage(path)
    file = path.parent / name
    st = file.stat()
    text = file.read_text()
    assert old in text and len(old) == len(new)
    file.write_text(text.replace(old, new))
    os.utime(file, ns=(st.st_atime_ns, st.st_mtime_ns))
    _forget_layers(path.parent)
    after = scene_cache.read_stage(path)
    assert len(reads) == 2
    assert after.content_hash() != before.content_hash()
    _same_scene(after, reader.read_stage(path))


def _forget_layers(folder: Path) -> None:
    """This process's USD keeps the layers it opened, and takes a file of the same time
    as unchanged: reload them (a run is a process of its own)."""
    from pxr import Sdf

    for f in folder.glob("*.usda"):
        layer = Sdf.Layer.Find(str(f))
        if layer is not None:
            layer.Reload(force=True)


def test_a_changed_or_touched_profile_makes_another_light(stage):
    path, reads = stage
    first = scene_cache.read_stage(path)
    ies = path.parent / "led.ies"
    os.utime(ies, (time.time() - 30, time.time() - 30))  # same bytes, another time
    touched = scene_cache.read_stage(path)
    assert len(reads) == 2 and touched.emitters[0].ies.stamp != first.emitters[0].ies.stamp
    _ies(ies, peak=200.0)
    _settle(path.parent)
    changed = scene_cache.read_stage(path)
    assert len(reads) == 3
    _same_scene(changed, reader.read_stage(path))
    _same_scene(scene_cache.read_stage(path), changed)
    assert len(reads) == 4


def test_files_written_just_before_the_read_are_not_trusted(stage):
    """A file modified within SETTLED_NS of the read may have changed while USD read it:
    the scene is not kept until a run finds it settled."""
    path, reads = stage
    (path.parent / "parts.usda").touch()
    scene_cache.read_stage(path)
    scene_cache.read_stage(path)
    assert len(reads) == 2
    _settle(path.parent)
    scene_cache.read_stage(path)
    scene_cache.read_stage(path)
    assert len(reads) == 3


def test_a_stage_that_did_not_compose_whole_is_not_kept(stage):
    """A missing file is only a warning outside the luminaire (here a sublayer that is a
    result layer, which a later run writes): no digest would see it appear."""
    path, reads = stage
    text = path.read_text().replace("@./parts.usda@", "@./parts.usda@, @./x.lumitrace.usda@")
    path.write_text(text)
    _settle(path.parent)
    scene = scene_cache.read_stage(path)
    assert any("x.lumitrace.usda" in w for w in scene.warnings)
    scene_cache.read_stage(path)
    assert len(reads) == 2
    (path.parent / "x.lumitrace.usda").write_text("#usda 1.0\n")
    _settle(path.parent)
    assert not scene_cache.read_stage(path).warnings == scene.warnings
    assert len(reads) == 3


def test_a_scene_with_warnings_about_its_values_is_kept(stage):
    """Warnings about what the files hold (here parts with no material) come back with
    the kept scene."""
    path, reads = stage
    first = scene_cache.read_stage(path)
    assert any("no material bound" in w for w in first.warnings)
    assert scene_cache.read_stage(path).warnings == first.warnings
    assert len(reads) == 1


def test_each_request_is_kept_apart(stage):
    path, reads = stage
    whole = scene_cache.read_stage(path)
    at_one = scene_cache.read_stage(path, time_code=1.0)
    assert len(reads) == 2 and at_one.time_code == 1.0 and whole.time_code is None
    assert scene_cache.read_stage(path, time_code=1.0).time_code == 1.0
    assert scene_cache.read_stage(path).time_code is None
    assert len(reads) == 2


def test_a_large_scene_is_not_kept(stage, tmp_path, monkeypatch):
    """Writing a large scene's entry costs its first run as much as it saves a later one."""
    path, reads = stage
    size = scene_cache._array_bytes(scene_cache.read_stage(path))
    # four triangles: world float64, two int32 indices, and their own float32 in frames
    assert size == 4 * (9 * 8 + 4 + 4) + 4 * 9 * 4
    monkeypatch.setattr(scene_cache, "MOST_BYTES", size - 1)
    (tmp_path / "cache" / scene_cache.entry_path(path).name).unlink()
    scene_cache.read_stage(path)
    scene_cache.read_stage(path)
    assert len(reads) == 3 and not list((tmp_path / "cache").glob("scene-*"))


def test_the_entries_used_least_recently_go(stage, tmp_path, monkeypatch):
    """Past MOST_ENTRIES, writing an entry removes the ones used least recently; taking a
    scene counts as a use."""
    path, reads = stage
    monkeypatch.setattr(scene_cache, "MOST_ENTRIES", 2)
    for code in (1.0, 2.0):
        scene_cache.read_stage(path, time_code=code)
    first = scene_cache.entry_path(path, time_code=1.0)
    os.utime(first, (time.time() - 100, time.time() - 100))
    scene_cache.read_stage(path, time_code=1.0)  # used again: the newest now
    assert len(reads) == 2
    os.utime(scene_cache.entry_path(path, time_code=2.0),
             (time.time() - 50, time.time() - 50))
    scene_cache.read_stage(path, time_code=3.0)
    left = sorted(p.name for p in (tmp_path / "cache").glob("scene-*"))
    assert left == sorted(scene_cache.entry_path(path, time_code=c).name for c in (1.0, 3.0))
    # what was vouched for a removed entry goes with it; of the digests of result layers
    # lumitrace wrote, those written least recently beyond as many go too
    cache = tmp_path / "cache"
    gone = scene_cache.entry_path(path, time_code=1.0).with_suffix(".vouched")
    kept = scene_cache.entry_path(path, time_code=3.0).with_suffix(".vouched")
    for k, layer in enumerate("abc"):
        scene_cache._note_written(str(tmp_path / f"{layer}.lumitrace.usda"), "d" * 64)
        when = time.time() - 30 + k
        os.utime(scene_cache._written_path(str(tmp_path / f"{layer}.lumitrace.usda")),
                 (when, when))
    gone.write_text("x"), kept.write_text("x")
    for code, age in ((1.0, 100), (3.0, 10)):
        os.utime(scene_cache.entry_path(path, time_code=code), (time.time() - age,) * 2)
    scene_cache.read_stage(path, time_code=4.0)
    assert sorted(p.name for p in cache.glob("scene-*.table")) == sorted(
        scene_cache.entry_path(path, time_code=c).name for c in (3.0, 4.0))
    assert kept.is_file() and not gone.exists()
    assert sorted(p.name for p in cache.glob("written-*")) == sorted(
        scene_cache._written_path(str(tmp_path / f"{layer}.lumitrace.usda")).name
        for layer in "bc")


def test_a_broken_entry_is_read_again(stage, tmp_path):
    path, reads = stage
    first = scene_cache.read_stage(path)
    (entry,) = (tmp_path / "cache").glob("scene-*")
    for damage in (b"", b"garbage", entry.read_bytes()[:200]):
        entry.write_bytes(damage)
        _same_scene(scene_cache.read_stage(path), first)
    assert len(reads) == 4
    scene_cache.read_stage(path)
    assert len(reads) == 4


@pytest.mark.parametrize("setting", ["off", "search path"])
def test_nothing_is_kept_when_told_or_when_a_search_path_could_change_a_read(
        stage, tmp_path, monkeypatch, setting):
    path, reads = stage
    if setting == "off":
        monkeypatch.setenv("LUMITRACE_CACHE_DIR", "off")
    else:
        monkeypatch.setenv(scene_cache.SEARCH_PATH_VARIABLE, str(tmp_path))
    scene_cache.read_stage(path)
    scene_cache.read_stage(path)
    assert len(reads) == 2
    assert not list((tmp_path / "cache").glob("scene-*"))


_PROBE = """
import json, sys
from lumitrace.stage.scene_cache import read_stage
scene = read_stage(sys.argv[1])
print(json.dumps({"hash": scene.content_hash(), "flux": scene.total_flux,
                  "usd": sorted(m for m in sys.modules if m.split(".")[0] == "pxr")[:3]}))
"""


def test_a_kept_scene_is_taken_without_loading_usd(stage, tmp_path):
    """In a fresh interpreter: the first read loads USD, the next one does not, and both
    give the scene USD reads."""
    path, _ = stage
    env = {**os.environ, "LUMITRACE_CACHE_DIR": str(tmp_path / "cache")}
    runs = [json.loads(subprocess.run([sys.executable, "-c", _PROBE, str(path)], env=env,
                                      capture_output=True, text=True, check=True).stdout)
            for _ in range(2)]
    assert runs[0]["usd"] and runs[1]["usd"] == []
    assert runs[0]["hash"] == runs[1]["hash"] == reader.read_stage(path).content_hash()


def test_a_trace_of_a_kept_scene_publishes_the_same_bits(stage, tmp_path):
    """The whole command, a fresh read then a kept one, same seed and photons: the same
    intensity map to the bit and the same files, USD loaded by the first only."""
    from lumitrace.publish.exr import read_intensity_exr

    path, _ = stage
    env = {**os.environ, "LUMITRACE_CACHE_DIR": str(tmp_path / "cache")}
    maps, files = [], []
    for i in range(2):
        out = tmp_path / f"out{i}"
        cmd = [sys.executable, "-X", "importtime", "-m", "lumitrace", "trace", str(path),
               "--photons", "20000", "--seed", "3", "--no-pictures", "--no-sublayer",
               "--quiet", "--out", str(out)]
        run = subprocess.run(cmd, env=env, capture_output=True, text=True)
        assert run.returncode == 0, run.stderr[-2000:]
        assert ("| pxr.Usd" in run.stderr) == (i == 0)
        maps.append(read_intensity_exr(out / "root.intensity.exr")[0])
        files.append({f.name: [line for line in f.read_text().splitlines()
                               if "_LUMITRACE_RUN" not in line and " run " not in line]
                      for f in (out / "root.ies", out / "root.ldt")})
    assert maps[0].keys() == maps[1].keys()
    for channel in maps[0]:
        assert np.array_equal(maps[0][channel], maps[1][channel], equal_nan=True), channel
    assert files[0] == files[1]


def test_a_sublayered_run_keeps_its_scene_for_the_next_run(stage, tmp_path):
    """The default command sublayers its result layer into the stage and rewrites it at
    every run; the run that wrote it vouches for it, so the next run takes the kept scene
    (USD not loaded), the scene USD reads. A layer changed by anyone else is read again,
    and a scene read with anyone else's bytes there is not vouched for."""
    path, _ = stage
    folder = path.parent
    env = {**os.environ, "LUMITRACE_CACHE_DIR": str(tmp_path / "cache")}

    emitted = []

    def traced() -> bool:
        """Whether a default trace of the stage loaded USD (any of its modules: the check of
        the root layer's sublayers and result opinions too); its flux in ``emitted``."""
        cmd = [sys.executable, "-X", "importtime", "-m", "lumitrace", "trace", str(path),
               "--photons", "4000", "--no-pictures", "--json", "--out", str(folder)]
        run = subprocess.run(cmd, env=env, capture_output=True, text=True)
        assert run.returncode == 0, run.stderr[-2000:]
        emitted.append(json.loads(run.stdout.strip().splitlines()[-1])["emitted_lm"])
        return "| pxr" in run.stderr

    layer = folder / "root.lumitrace.usda"
    assert traced() and layer.is_file()  # the first run sublayers its layer: the root changed
    _settle(folder)
    assert traced()  # read with the layer, kept, then the layer rewritten and vouched for
    (entry,) = (tmp_path / "cache").glob("scene-*.table")
    written = entry.stat().st_ino
    assert [traced() for _ in range(2)] == [False, False]  # each run vouches for the next
    # beside the entry, which is not written again (its arrays can be 32 MB)
    assert entry.stat().st_ino == written and entry.with_suffix(".vouched").is_file()
    kept = scene_cache.read_stage(path)
    assert os.path.realpath(layer) in kept.input_files()
    _same_scene(kept, reader.read_stage(path))
    layer.write_text(layer.read_text() + "\n")  # anyone else's edit, even a blank line
    _settle(folder)
    assert traced()  # read again; its scene was read with bytes lumitrace did not write
    assert traced() and not traced()  # so only the run after it vouches again
    # anyone else's bytes that change the scene (a second light put in the layer): the
    # run that writes over them must not vouch for the scene read with them
    text = layer.read_text()
    at = text.index("\n{\n", text.index('over "Luminaire"')) + 3
    layer.write_text(text[:at] + '    def DiskLight "Extra" (\n        prepend apiSchemas = '
                     '["LumitraceEmitterAPI"]\n    )\n    {\n        float inputs:radius = 2\n'
                     f'        float lumitrace:luminousFlux = {FLUX:g}\n    }}\n' + text[at:])
    _settle(folder)
    assert traced() and traced() and not traced()
    assert emitted[-3:] == [2 * FLUX, FLUX, FLUX]  # read with the edit; then without it
    _same_scene(scene_cache.read_stage(path), reader.read_stage(path))
def test_default_runs_at_the_same_moment_leave_a_kept_scene_that_is_the_stage(stage,
                                                                             tmp_path):
    """Three default (sublayered) runs of one stage started together, twice: each ends
    well, each traces the stage's flux, and a scene kept after them is the one USD reads
    (they publish in turn; each vouches only for what it read). One that read the result
    layer another had just rewritten vouches for nothing (a lost hit, never a wrong
    scene): the next run alone leaves a kept scene again."""
    path, _ = stage
    folder = path.parent
    env = {**os.environ, "LUMITRACE_CACHE_DIR": str(tmp_path / "cache")}
    cmd = [sys.executable, "-m", "lumitrace", "trace", str(path), "--photons", "4000",
           "--no-pictures", "--json", "--no-progress", "--out", str(folder)]
    assert subprocess.run(cmd, env=env, capture_output=True).returncode == 0
    _settle(folder)
    for _ in range(2):
        runs = [subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True) for _ in range(3)]
        for run in runs:
            out, err = run.communicate(timeout=300)
            assert run.returncode == 0, err[-2000:]
            assert json.loads(out.strip().splitlines()[-1])["emitted_lm"] == FLUX
    entry = next((tmp_path / "cache").glob("scene-*.table"))
    kept = scene_cache._kept_scene(entry)
    if kept is not None:
        _same_scene(kept, reader.read_stage(path))
    assert subprocess.run(cmd, env=env, capture_output=True).returncode == 0
    kept = scene_cache._kept_scene(entry)
    assert kept is not None
    _same_scene(kept, reader.read_stage(path))




def test_a_file_hashed_once_in_a_process_is_read_again_after_any_write(tmp_path,
                                                                        monkeypatch):
    """A run hashes its files when it takes a scene and again when it vouches: the second
    time a settled file with the same stat is not read again, and any write since (even of
    the same size with its modification time put back) makes it read again."""
    monkeypatch.setattr(scene_cache, "SETTLED_NS", 20_000_000)  # 20 ms, not 2 s
    monkeypatch.setattr(scene_cache, "_taken", {})
    reads = []
    real = scene_cache.readable_digest
    monkeypatch.setattr(scene_cache, "readable_digest",
                        lambda f: reads.append(f) or real(f))
    layer = tmp_path / "root.usda"
    layer.write_text("#usda 1.0\n(doc = \"a\")\n")
    fresh = scene_cache._digest(str(layer))
    assert scene_cache._digest(str(layer)) == fresh and len(reads) == 2  # too fresh to keep
    time.sleep(0.05)
    assert scene_cache._digest(str(layer)) == fresh and len(reads) == 3
    assert scene_cache._digest(str(layer)) == fresh and len(reads) == 3  # settled: kept
    st = layer.stat()
    layer.write_text("#usda 1.0\n(doc = \"b\")\n")  # same size, its time put back
    os.utime(layer, ns=(st.st_atime_ns, st.st_mtime_ns))
    edited = scene_cache._digest(str(layer))
    assert edited != fresh and edited == real(str(layer)) and len(reads) == 4


#: A default trace killed (SIGKILL, which no handler sees) at a chosen moment of keeping
#: its kept scene valid: ``vouch`` as it is called (the result layer written, nothing
#: noted), ``note`` after the layer's new digest is noted, before the vouch is written.
_KILLED_AT = """
import os, signal, sys
from lumitrace.stage import scene_cache

moment = sys.argv.pop(1)
if moment == "vouch":
    scene_cache.vouch = lambda *a, **k: os.kill(os.getpid(), signal.SIGKILL)
else:
    real = scene_cache.write_kept

    def write_kept(path, data):
        if str(path).endswith(".vouched"):
            os.kill(os.getpid(), signal.SIGKILL)
        return real(path, data)

    scene_cache.write_kept = write_kept
from lumitrace.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("moment", ["vouch", "note"])
def test_a_run_killed_while_vouching_leaves_nothing_that_is_taken_wrongly(stage, tmp_path,
                                                                          moment):
    """A default run killed after rewriting its result layer, before its vouch is written
    (a vouch of the run before it on disk): the next run reads the stage with USD, traces
    its flux and ends well; the run after that takes the kept scene again; the scene kept
    is the one USD reads, and the result layer is whole."""
    path, _ = stage
    folder = path.parent
    env = {**os.environ, "LUMITRACE_CACHE_DIR": str(tmp_path / "cache")}
    args = ["trace", str(path), "--photons", "4000", "--no-pictures", "--json",
            "--no-progress", "--out", str(folder)]
    cmd = [sys.executable, "-X", "importtime", "-m", "lumitrace", *args]

    def traced() -> bool:
        """Whether a default trace loaded USD; it ends well with the stage's flux."""
        run = subprocess.run(cmd, env=env, capture_output=True, text=True)
        assert run.returncode == 0, run.stderr[-2000:]
        assert json.loads(run.stdout.strip().splitlines()[-1])["emitted_lm"] == FLUX
        return "| pxr" in run.stderr

    assert traced()
    _settle(folder)
    assert traced() and not traced()  # vouched for: a vouch file stands beside the entry
    (entry,) = (tmp_path / "cache").glob("scene-*.table")
    assert entry.with_suffix(".vouched").is_file()
    layer = folder / "root.lumitrace.usda"
    before = layer.read_bytes()
    killed = subprocess.run([sys.executable, "-c", _KILLED_AT, moment, *args], env=env,
                            capture_output=True, text=True)
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    assert layer.read_bytes() != before  # killed after the layer was rewritten
    assert traced()  # the layer holds bytes nothing vouched for: read with USD
    assert not traced()  # and that run vouched again
    _same_scene(scene_cache.read_stage(path), reader.read_stage(path))
    from pxr import Sdf
    assert Sdf.Layer.FindOrOpen(str(layer)) is not None  # whole: it parses
