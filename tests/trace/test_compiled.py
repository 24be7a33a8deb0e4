"""The kernels' ahead-of-time build against numba's JIT: the same photons bit for bit, no
call that does not fit the build reaches it, and a run with the build loads no compiler."""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lumitrace.stage.reader import read_stage
from lumitrace.trace import compiled
from lumitrace.trace.job import BatchJob
from lumitrace.trace.prepared import prepare
from lumitrace.trace.tracer import RAY_EPSILON, trace_batch

from helpers.tallies import same_tally

STAGES = Path(__file__).resolve().parents[2] / "stages"
needs_build = pytest.mark.skipif(
    compiled.backend() != "aot",
    reason="no ahead-of-time build of the kernels here (built by tools/setup.sh)")


def _jit_only(monkeypatch):
    for name in compiled.ENTRY_POINTS:
        monkeypatch.setattr(getattr(compiled, name), "built", [])


@needs_build
@pytest.mark.parametrize("stage", ["downlight.usda", "warm_downlight.usda", "louvre.usda",
                                   "reference/fresnel_slab.usda",
                                   "reference/integrating_sphere.usda"])
def test_the_build_traces_the_jits_photons_bit_for_bit(stage, monkeypatch):
    scene = read_stage(STAGES / stage)
    ps = prepare(scene)
    jobs = [BatchJob(e, 1000, 6000, 11, 16) for e in range(len(scene.emitters))]
    compiled.fallbacks.clear()
    built = [trace_batch(ps, j, records=True, exit_rays=True) for j in jobs]
    plain = [trace_batch(ps, j) for j in jobs]
    assert not compiled.fallbacks  # every call fitted the build
    _jit_only(monkeypatch)
    for job, a, b in zip(jobs, built, plain):
        same_tally(a, trace_batch(ps, job, records=True, exit_rays=True))
        same_tally(b, trace_batch(ps, job))
    assert sum(t.escaped for t in built) > 1000 and sum(t.part_hits.sum() for t in built) > 1000


def _start_args(p):
    n = p.shape[1]
    d = np.ascontiguousarray(p[::-1])
    return (p, d, d.copy(), np.array([0.1, 0.2, 0.3]), 2.0, RAY_EPSILON,
            np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3), np.float32),
            np.empty((n, 3), np.float32))


@needs_build
def test_a_call_the_build_does_not_fit_goes_to_the_jit_with_the_same_result():
    p = np.random.default_rng(3).normal(size=(3, 40))
    compiled.fallbacks.clear()
    fits = _start_args(p)
    compiled.start(*fits)
    assert not compiled.fallbacks
    other = _start_args(np.asfortranarray(p))  # another layout: the build reads it wrong
    compiled.start(*other)
    assert compiled.fallbacks["start"] == 1
    for a, b in zip(fits[6:], other[6:]):
        assert np.array_equal(a, b)


def test_argument_checks_take_exactly_the_built_types():
    checks = tuple(compiled._check(s) for s in
                   (["array", "float64", 2, "C", True], "int64", "float64", "bool", "uint64",
                    ["array", "int32", 1, "A", False]))
    good = (np.zeros((2, 3)), 4, 0.5, True, np.uint64(9), np.zeros(5, np.int32))
    assert compiled._fits(checks, good)
    assert compiled._fits(checks, (np.zeros((2, 3)), np.int64(4), np.float64(0.5),
                                   np.bool_(False), np.uint64(0), np.zeros(9, np.int32)[::2]))
    frozen = np.zeros((2, 3))
    frozen.flags.writeable = False
    wrong = [
        (np.zeros((2, 3), np.float32),) + good[1:],  # dtype
        (np.zeros((2, 3, 1)),) + good[1:],  # dimensions
        (np.zeros((3, 2)).T,) + good[1:],  # not C-contiguous
        (frozen,) + good[1:],  # read-only, but written to
        (np.zeros((2, 3)).tolist(),) + good[1:],  # not an array
        good[:1] + (4.0,) + good[2:],  # a float for an integer
        good[:1] + (np.int32(4),) + good[2:],  # another integer width
        good[:1] + (True,) + good[2:],  # a bool for an integer
        good[:2] + (1,) + good[3:],  # an int for a float: the JIT would specialise
        good[:4] + (9,) + good[5:],  # a Python int for a uint64
        good[:5] + (np.zeros(5, np.int64),),  # dtype of an any-layout array
        good[:5],  # too few arguments
    ]
    for args in wrong:
        assert not compiled._fits(checks, args)


def test_the_build_is_named_by_the_kernels_sources(tmp_path, monkeypatch):
    for name in compiled.SOURCES:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(compiled.HERE / name, tmp_path / name)
    key = compiled.source_key()
    monkeypatch.setattr(compiled, "HERE", tmp_path)
    assert compiled.source_key() == key
    with open(tmp_path / "kernels" / "binning.py", "a") as f:
        f.write("\n")
    assert compiled.source_key() != key
    key = compiled.source_key()
    monkeypatch.setattr(compiled, "cpu_key", lambda: "another CPU")  # built for another CPU
    assert compiled.source_key() != key
    monkeypatch.undo()
    monkeypatch.setattr(compiled, "HERE", tmp_path)
    so, types = compiled.build_paths(tmp_path)
    assert so.name.startswith(compiled.MODULE + "-" + compiled.source_key())
    assert types.suffix == ".json" and so.parent == types.parent == tmp_path


RUN = """
import sys
from lumitrace import api
from lumitrace.trace import compiled
result = api.trace(api.read_stage(sys.argv[1]),
                   api.TraceSettings(photons=20000, resolution=8, workers="threads"))
print(compiled.backend(), "numba" in sys.modules, "llvmlite" in sys.modules, result.photons,
      repr(result.relative_error))
"""


@needs_build
def test_a_run_with_the_build_loads_neither_numba_nor_llvm():
    stage = str(STAGES / "downlight.usda")
    runs = {}
    for mode in ("", "jit"):
        env = dict(os.environ, LUMITRACE_KERNELS=mode)
        out = subprocess.run([sys.executable, "-c", RUN, stage], env=env, capture_output=True,
                             text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        runs[mode] = out.stdout.split()
    assert runs[""][:3] == ["aot", "False", "False"]
    assert runs["jit"][:3] == ["jit", "True", "True"]
    assert runs[""][3:] == runs["jit"][3:] and runs[""][3] == "20000"  # the same map


@needs_build
def test_the_builds_types_are_one_signature_per_kernel():
    _, types = compiled.build_paths()
    table = json.loads(types.read_text())
    assert sorted(table) == sorted(compiled.ENTRY_POINTS)
    assert all(len(v) == 1 for v in table.values())  # call sites pass canonical types


def test_a_missing_stale_or_broken_build_leaves_the_jit_and_says_why(tmp_path, monkeypatch):
    real = compiled.build_paths
    monkeypatch.setattr(compiled, "build_paths", lambda directory=None: real(tmp_path))
    monkeypatch.delenv("LUMITRACE_KERNELS", raising=False)
    so, types = real(tmp_path)
    built, state = compiled._load()
    assert state == "missing" and not any(built.values())
    (tmp_path / (compiled.MODULE + "-0123456789abcdef.json")).write_text("{}")
    assert compiled._load()[1] == "stale"  # another source's build
    so.write_bytes(b"not a shared object")
    types.write_text(json.dumps({"start": [["start_0", ["int64"]]]}))
    built, state = compiled._load()
    assert state == "unloadable" and not any(built.values())
    monkeypatch.setenv("LUMITRACE_KERNELS", "jit")
    assert compiled._load()[1] == "asked"


def test_an_edit_of_the_kernels_leaves_the_build_and_says_so(tmp_path):
    if compiled.backend() != "aot":
        pytest.skip("no ahead-of-time build of the kernels here (built by tools/setup.sh)")
    folder = tmp_path / "trace"
    shutil.copytree(compiled.HERE, folder, ignore=shutil.ignore_patterns("*.pyc"))
    with open(folder / "kernels" / "scattering.py", "a") as f:
        f.write("\n# an edit\n")
    code = ("import sys, lumitrace.trace as t; t.__path__.insert(0, sys.argv[1]); "
            "from lumitrace.trace import compiled; print(compiled.backend(), compiled.note())")
    out = subprocess.run([sys.executable, "-c", code, str(folder)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("jit the photon kernels' ahead-of-time build is out of date")
