"""numba's disk cache of the photon kernels is keyed on all kernel sources: an edit of one
kernel file recompiles the kernels of the others, which inline its helpers."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

from lumitrace.trace import kernel_sources, kernels

# texels (binning.py) compiled or loaded from the cache in a copy of the trace package;
# prints the cache's hits and misses and the cube-map texels it returns
CALL = """
import sys, numpy as np
import lumitrace.trace as t
t.__path__.insert(0, sys.argv[1])
from lumitrace.trace import kernels
from lumitrace.trace.tracer import _CUBE_LAYOUT
assert kernels.__file__.startswith(sys.argv[1])
d = np.ascontiguousarray(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]).T)
out = kernels.texels(d, 4, _CUBE_LAYOUT)
s = kernels.texels.stats
print(sum(s.cache_hits.values()), sum(s.cache_misses.values()), list(out))
"""


def test_every_kernel_is_cached_with_the_digest_of_all_sources():
    for name in ("start", "cull", "bounce", "emit_photons", "scatter_many", "intersect",
                 "texels", "gonio_bins"):
        locator = getattr(kernels, name)._cache._impl._locator
        assert locator.get_source_stamp() == kernel_sources.digest()
        assert type(locator).__name__.startswith("Kernel")


def test_the_digest_changes_with_any_kernel_source(tmp_path):
    for name in kernel_sources.SOURCES:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(kernel_sources.HERE / name, tmp_path / name)
    key = kernel_sources.digest(tmp_path)
    assert key == kernel_sources.digest()
    for name in kernel_sources.SOURCES:
        text = (tmp_path / name).read_bytes()
        (tmp_path / name).write_bytes(text + b"\n")
        assert kernel_sources.digest(tmp_path) != key, name
        (tmp_path / name).write_bytes(text)
    assert kernel_sources.digest(tmp_path) == key


def test_an_edit_of_another_kernel_file_recompiles(tmp_path):
    folder = tmp_path / "trace"
    shutil.copytree(kernel_sources.HERE, folder,
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))

    def call():
        out = subprocess.run([sys.executable, "-c", CALL, str(folder)], capture_output=True,
                             text=True, timeout=300,
                             env=dict(os.environ, LUMITRACE_KERNELS="jit"))
        assert out.returncode == 0, out.stderr
        hits, misses, texels = out.stdout.strip().split(" ", 2)
        return int(hits), int(misses), texels

    first = call()
    assert first[:2] == (0, 1)  # compiled, and written to the cache
    assert call() == (1, 0, first[2])  # loaded from it
    with open(folder / "kernels" / "maths.py", "a") as f:  # not texels' own file
        f.write("\n# an edit\n")
    assert call() == (0, 1, first[2])  # compiled again
