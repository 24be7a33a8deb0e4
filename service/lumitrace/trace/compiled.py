"""The photon kernels as the tracer calls them: an ahead-of-time build of
:mod:`lumitrace.trace.kernels` when one matches their source, else numba's JIT.

Loading numba and LLVM costs a process about 1 CPU s and 150 MB before its first photon
(every worker process pays it again). The build (:mod:`lumitrace.trace.aot`, run at
install) compiles the same functions with the same compiler, for this machine's CPU as
the JIT does, into an extension module kept in ``__pycache__`` beside them, named by a
hash of their sources and of the CPU: loading it takes under a millisecond and needs
neither. Its functions take exactly the argument types they
were built for and, unlike the JIT, do not check them, so every call is checked here
(about 0.3 us an argument); a call that does not fit, a missing or stale build, or
``LUMITRACE_KERNELS=jit`` goes to the JIT instead: slower to start, never different.
"""
from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import json
import os
import platform
from collections import Counter
from pathlib import Path

import numpy as np

from ..film import accumulate as _accumulate, pullpush as _pullpush
from . import kernel_sources

#: The kernels the tracer calls, in the order the build exports them.
ENTRY_POINTS = ("start", "cull", "bounce", "emit_photons", "scatter_many", "intersect",
                "push_level", "pair_quads", "add_bins")
#: The sources whose text the compiled code depends on (the kernels' constants included).
SOURCES = kernel_sources.SOURCES
MODULE = "kernels_aot"
HERE = Path(__file__).resolve().parent
#: Calls that went to the JIT although a build was loaded, by kernel (see :func:`backend`).
fallbacks: Counter = Counter()

_SCALARS = {"int64": (int, np.int64), "float64": (float, np.float64),
            "bool": (bool, np.bool_), "uint64": (np.uint64,)}


def cpu_key() -> str:
    """The CPU a build is made for: its model and instruction-set flags where the system
    lists them (Linux), else what the platform module says. A build made for another CPU
    could use instructions this one lacks, so it is not loaded."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            lines: dict = {}
            for line in f:
                key = line.split(":", 1)[0].strip()
                if key in ("model name", "flags", "Features") and key not in lines:
                    lines[key] = line.strip()
                if not line.strip() and lines:  # the first processor's block is enough
                    break
        if lines:
            return repr(sorted(lines.items()))
    except OSError:
        pass
    return repr((platform.machine(), platform.processor()))


def source_key() -> str:
    """A hash of the kernels' sources, the material codes they compare against, the
    Python, numpy and CPU they are built for: the build's name."""
    h = hashlib.sha256(kernel_sources.digest(HERE).encode())
    h.update(repr((np.__version__, platform.machine(), cpu_key())).encode())
    return h.hexdigest()[:16]


def build_paths(directory: Path | None = None) -> tuple[Path, Path]:
    """Where the build for the current sources lives: the extension module and its
    argument types (JSON)."""
    d = directory or HERE / "__pycache__"
    stem = f"{MODULE}-{source_key()}"
    return (d / (stem + importlib.machinery.EXTENSION_SUFFIXES[0]), d / (stem + ".json"))


#: numpy's array flag bits (``ndarray.flags.num``) a build's array argument needs.
_C, _F, _ALIGNED, _WRITEABLE = 0x1, 0x2, 0x100, 0x400


def _check(spec: list) -> tuple:
    """One argument's check from its type as the build wrote it (("array", dtype, ndim,
    layout, writeable) or the name of a scalar type): (dtype, ndim, flag bits it needs)
    for an array, (None, the Python and numpy types) for a scalar."""
    if isinstance(spec, str):
        return (None, _SCALARS[spec])
    _, dtype, ndim, layout, writeable = spec
    need = _ALIGNED | (_WRITEABLE if writeable else 0) | {"C": _C, "F": _F}.get(layout, 0)
    return (np.dtype(dtype), ndim, need)


def _fits(checks: tuple, args: tuple) -> bool:
    """Whether ``args`` are exactly the types a build's function was compiled for (a
    fraction of a microsecond an argument: a many-emitter run calls a kernel per batch)."""
    if len(args) != len(checks):
        return False
    ndarray = np.ndarray
    for a, c in zip(args, checks):
        dtype = c[0]
        if dtype is None:  # a scalar
            if type(a) not in c[1]:
                return False
        elif type(a) is not ndarray or a.ndim != c[1] or \
                (a.dtype is not dtype and a.dtype != dtype) or \
                a.flags.num & c[2] != c[2]:
            return False
    return True


class Kernel:
    """One entry point: the build's functions (with their argument checks) first, the
    JIT for any call none of them fits."""

    def __init__(self, name: str, built: list):
        self.name = name
        self.built = built  # [(function, checks)]
        self._jit = None

    def __call__(self, *args):
        for fn, checks in self.built:
            if _fits(checks, args):
                return fn(*args)
        if self.built:
            fallbacks[self.name] += 1
        if self._jit is None:
            from . import kernels

            self._jit = getattr(kernels, self.name)
        return self._jit(*args)


def _load() -> tuple[dict, str]:
    """The entry points, from the build when there is a current one, and why not if not:
    "built", "asked" (``LUMITRACE_KERNELS=jit``), "missing", "stale" (a build of other
    sources is there) or "unloadable"."""
    built: dict = {name: [] for name in ENTRY_POINTS}
    if os.environ.get("LUMITRACE_KERNELS", "").lower() == "jit":
        return built, "asked"
    try:
        so, types = build_paths()
        if not (so.exists() and types.exists()):
            return built, "stale" if any(so.parent.glob(MODULE + "-*")) else "missing"
        table = json.loads(types.read_text())
        spec = importlib.util.spec_from_file_location(MODULE, so)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        for name, exports in table.items():
            if name in built:
                built[name] = [(getattr(module, export), tuple(_check(s) for s in args))
                               for export, args in exports]
    except (OSError, ImportError, ValueError, KeyError, AttributeError):
        return {name: [] for name in ENTRY_POINTS}, "unloadable"
    return built, "built"


_built, _state = _load()
start, cull, bounce, emit_photons, scatter_many, intersect, push_level, pair_quads, \
    add_bins = (Kernel(n, _built[n]) for n in ENTRY_POINTS)
# the film (which comes before the tracer) filters with the compiled push level and adds
# a batch's escapes with the compiled scatter
_pullpush.use_compiled_level(push_level)
_accumulate.use_compiled_scatter(add_bins)


def backend() -> str:
    """"aot" when the kernels come from a current build, "jit" when from numba."""
    return "aot" if _state == "built" else "jit"


def note() -> str | None:
    """What a user should hear about the kernels, if anything: a build that is there but
    out of date or unreadable (no build at all is the set-up's to say, once)."""
    if _state not in ("stale", "unloadable"):
        return None
    what = "out of date" if _state == "stale" else "unreadable"
    return (f"the photon kernels' ahead-of-time build is {what} (`python -m "
            "lumitrace.trace.aot` rebuilds it): numba compiles them instead, which costs "
            "about a second at start")
