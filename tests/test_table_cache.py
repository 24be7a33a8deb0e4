"""Layout tables kept on disk (lumitrace.table_cache): read back equal to what is made,
keyed on the sources, safe against broken and unwritable folders, and a run that reads
them writes the same files as one that makes them."""
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lumitrace import table_cache
from lumitrace.film import cubemap, pullpush
from lumitrace.photometry import bug, peak, ugr
from lumitrace.publish import latlong

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A fresh cache folder, and every kept table forgotten in this process."""
    monkeypatch.setenv("LUMITRACE_CACHE_DIR", str(tmp_path / "cache"))
    tables = [pullpush._pyramid, cubemap._seams, latlong._latlong_taps, peak._cell_directions,
              peak._cell_omegas, bug.zone_of_cell, ugr._kept_layout_tables]
    for t in tables:
        t.cache_clear()
    yield tmp_path / "cache"
    for t in tables:
        t.cache_clear()


def _equal(a, b) -> bool:
    """Deep equality of tables: arrays bit for bit (dtype and shape), containers alike."""
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, (tuple, list)):
        return type(a) is type(b) and len(a) == len(b) and all(map(_equal, a, b))
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(_equal(getattr(a, f), getattr(b, f))
                                          for f in a.__dataclass_fields__)
    return a == b


CASES = [(pullpush._pyramid, (64,)), (cubemap._seams, (32,)),
         (latlong._latlong_taps, (16, 64, "Z")), (peak._cell_directions, ()),
         (peak._cell_omegas, ()), (bug.zone_of_cell, ()),
         (ugr._kept_layout_tables, (tuple(np.arange(0.0, 360.0, 15.0)),
                                    tuple(ugr.DEFAULT_GAMMAS), "none"))]


@pytest.mark.parametrize("fn,args", CASES, ids=lambda c: getattr(c, "__qualname__", ""))
def test_a_kept_table_reads_back_equal_to_the_one_made(folder, fn, args):
    made = fn.uncached(*args)
    first = fn(*args)  # made and kept
    files = list(folder.glob(f"{fn.__module__}.{fn.__qualname__}-*.table"))
    assert len(files) == 1
    fn.cache_clear()
    read = fn(*args)  # read back from the file
    assert read is not first
    assert _equal(made, first) and _equal(made, read)
    arrays = [read] if isinstance(read, np.ndarray) else \
        [a for a in (read if isinstance(read, tuple) else ()) if isinstance(a, np.ndarray)]
    assert all(not a.flags.writeable for a in arrays)  # shared: read-only


def test_an_edited_source_makes_a_new_key_and_the_oldest_tables_go(folder, tmp_path,
                                                                   monkeypatch):
    """The key follows every source file (here a copy of two of them, so the package itself
    is left alone): touching one makes a new key. The tables of the
    :data:`~lumitrace.table_cache.KEPT_STAMPS` sources stamps written last before it stay
    (another install sharing the folder keeps its own); older ones go."""
    package = tmp_path / "package"
    (package / "film").mkdir(parents=True)
    for name in ("film/pullpush.py", "film/cubemap.py"):
        (package / name).write_bytes((Path(pullpush.__file__).parents[1] / name).read_bytes())
    (package / "film" / "__pycache__").mkdir()
    (package / "film" / "__pycache__" / "ignored.py").write_text("# a first")
    monkeypatch.setattr(table_cache, "_PACKAGE", package)
    table_cache.sources_stamp.cache_clear()
    source = package / "film" / "cubemap.py"
    made = []
    try:
        first = table_cache.sources_stamp()
        (package / "film" / "__pycache__" / "ignored.py").write_text("# not a source")
        table_cache.sources_stamp.cache_clear()
        assert table_cache.sources_stamp() == first  # bytecode folders are not sources
        for k in range(table_cache.KEPT_STAMPS + 2):
            if k:  # an edit: a new stamp
                st = source.stat()
                os.utime(source, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
                table_cache.sources_stamp.cache_clear()
            pullpush._pyramid.cache_clear()
            pullpush._pyramid(8)
            (new,) = set(folder.glob("*._pyramid-*.table")) - set(made)
            os.utime(new, ns=(k * 10**9, k * 10**9))  # written in this order
            made.append(new)
            assert len({p.name.rpartition("-")[2] for p in made}) == k + 1
        kept = sorted(p.name for p in folder.glob("*._pyramid-*.table"))
        assert kept == sorted(p.name for p in made[-table_cache.KEPT_STAMPS - 1:])
    finally:
        table_cache.sources_stamp.cache_clear()


def test_two_installs_sharing_the_folder_each_keep_their_tables(folder, monkeypatch):
    """Runs of two sources stamps in turn (a release and a checkout) each read their own
    table after the first: none is made again."""
    stamps = ["aaaaaaaaaaaaaaaaaaaa", "bbbbbbbbbbbbbbbbbbbb"]
    made = []
    for turn in range(4):
        monkeypatch.setattr(table_cache, "sources_stamp", lambda s=stamps[turn % 2]: s)
        pullpush._pyramid.cache_clear()
        before = {p.name: p.stat().st_ino for p in folder.glob("*.table")} \
            if folder.exists() else {}
        pullpush._pyramid(8)
        after = {p.name: p.stat().st_ino for p in folder.glob("*.table")}
        made.append(sorted(set(after.items()) - set(before.items())))
    assert [len(m) for m in made] == [1, 1, 0, 0]


@pytest.mark.parametrize("damage", ["not a table", "cut short", "empty", "spans past the end"])
def test_a_broken_file_is_made_again_and_replaced_whole(folder, damage):
    want = cubemap._seams.uncached(16)
    cubemap._seams(16)
    (path,) = folder.glob("*._seams-*.table")
    whole = path.read_bytes()
    path.write_bytes({"not a table": b"\x80\x05 not a pickle", "cut short": whole[:-100],
                      "empty": b"", "spans past the end": whole[:24] + b"\xff" * 16
                      + whole[40:]}[damage])  # (the first buffer's offset and size)
    assert table_cache.read_table(path) == (False, None)
    cubemap._seams.cache_clear()
    assert _equal(cubemap._seams(16), want)
    assert path.read_bytes() == whole


def test_an_unwritable_folder_or_off_costs_only_the_making(tmp_path, monkeypatch, folder):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("LUMITRACE_CACHE_DIR", str(blocker / "cache"))
    assert _equal(cubemap._seams(8), cubemap._seams.uncached(8))
    monkeypatch.setenv("LUMITRACE_CACHE_DIR", "off")
    cubemap._seams.cache_clear()
    assert table_cache.cache_folder() is None
    assert _equal(cubemap._seams(8), cubemap._seams.uncached(8))
    assert not folder.exists()


def test_a_run_that_reads_the_tables_writes_what_a_run_that_makes_them_writes(tmp_path):
    """The same command twice, with an empty cache folder and then with the tables the first
    run kept: the photometric files are byte for byte the same (but for the run's id), the EXR's channels bit for
    bit."""
    from lumitrace.publish.exr import read_intensity_exr

    stage = ROOT / "stages" / "reference" / "lambertian_disc.usda"
    env = dict(os.environ, LUMITRACE_CACHE_DIR=str(tmp_path / "cache"))
    outs = []
    for k in range(2):
        out = tmp_path / f"out{k}"
        subprocess.run([sys.executable, "-m", "lumitrace", "trace", str(stage), "--photons",
                        "200000", "--no-pictures", "--quiet", "--no-sublayer", "--out",
                        str(out)], check=True, env=env)
        outs.append(out)
        if k == 0:
            assert len(list((tmp_path / "cache").glob("*.table"))) >= 5
    for suffix in (".ies", ".ldt"):  # all but the line naming the run (its own id)
        a, b = ([line for line in (o / f"lambertian_disc{suffix}").read_bytes().splitlines()
                 if b" run " not in line and not line.startswith(b"[_LUMITRACE_RUN]")]
                for o in outs)
        assert len(a) > 10 and a == b
    maps = [read_intensity_exr(o / "lambertian_disc.intensity.exr")[0] for o in outs]
    for ch in maps[0]:
        assert np.array_equal(maps[0][ch], maps[1][ch]), ch


def test_processes_making_the_same_table_at_once_leave_one_whole_file(folder):
    """Four processes started together make the same table into one empty folder: one file
    is left, whole, and equal to the table."""
    code = ("import sys; from lumitrace.film import pullpush; print('ready', flush=True); "
            "sys.stdin.read(); pullpush._pyramid(48)")
    env = dict(os.environ, LUMITRACE_CACHE_DIR=str(folder))
    procs = [subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True, env=env) for _ in range(4)]
    assert all(p.stdout.readline().strip() == "ready" for p in procs)
    for p in procs:  # released together, once every one has loaded lumitrace
        p.stdin.close()
    assert all(p.wait(timeout=120) == 0 for p in procs)
    files = list(folder.iterdir())
    assert [f.suffix for f in files] == [".table"]
    assert _equal(table_cache.read_table(files[0])[1], pullpush._pyramid.uncached(48))


class _Planted:
    """A pickle that runs code as it loads: it leaves a marker file."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (Path.write_text, (Path(self.marker), "ran"))


@pytest.mark.skipif(os.getuid() != 0, reason="giving a file to another user needs root")
def test_a_planted_table_is_never_loaded(folder, tmp_path):
    """A crafted pickle in the place of a kept table is not loaded (its code does not run)
    when the file is another user's, or when the folder is writable by others; the table
    is made again, right. This user's own file in a private folder is read as before."""
    want = cubemap._seams.uncached(8)
    cubemap._seams(8)
    (path,) = folder.glob("*._seams-*.table")
    marker = tmp_path / "ran"
    for case in ("another user's file", "a folder others may write"):
        path.write_bytes(table_cache._encoded(_Planted(marker)))
        if case == "another user's file":
            os.chown(path, 65534, 65534)
        else:
            os.chown(path, 0, 0)
            folder.chmod(0o777)
        cubemap._seams.cache_clear()
        assert _equal(cubemap._seams(8), want), case
        assert not marker.exists(), case
    folder.chmod(0o700)
    path.write_bytes(table_cache._encoded(_Planted(marker)))  # this user's, private: it is read
    cubemap._seams.cache_clear()
    cubemap._seams(8)
    assert marker.exists()
