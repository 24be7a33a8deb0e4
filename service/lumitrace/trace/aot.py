"""Build the photon kernels ahead of time (install time: ``python -m lumitrace.trace.aot``).

Traces a few photons of small scenes that use every kernel (plain, spectral, with records
and exit rays, with polarisation) through numba's JIT, so its on-disk cache is warm, then
compiles each signature those calls used with numba's ``pycc`` into one extension module
(see :mod:`lumitrace.trace.compiled`) with the JIT's options: the GIL released, numpy's
floating-point error model, and this machine's CPU and instruction set, which the escapes'
binning needs to run on several at once. Neither allows fast-math or fused multiply-adds,
so the numbers are the same on any CPU. It needs a C
compiler to link; without one the kernels stay JIT-compiled, and the build says so.
"""
from __future__ import annotations

import json
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from . import compiled


def warm_up() -> None:
    """Call every entry point with the argument types runs use (so a JIT compiles or loads
    them, or a build is checked to fit them)."""
    from ..scene import Emitter, Material, Scene
    from .job import BatchJob
    from .prepared import prepare
    from .scattering import MaterialTable, scatter
    from .tracer import trace_batch

    tri = np.array([[[-1.0, -1.0, -0.5], [1.0, -1.0, -0.5], [1.0, 1.0, -0.5]]])
    e = Emitter(path="/L", kind="disk", flux=1.0, to_world=np.eye(4), radius=0.1)
    glass = Material("/M", "dielectric", ior=1.5)
    paint = Material("/M", "diffuse", reflectance=0.8,
                     reflectance_spectrum=tuple(np.linspace(0.5, 0.9, 401)))
    for material in (glass, paint):
        scene = Scene(tri, np.zeros(1, np.int32), np.zeros(1, np.int32), (material,),
                      ("/P",), (e,))
        for records in (False, True):  # whole paths; then a bounce at a time
            trace_batch(prepare(scene), BatchJob(0, 0, 16, 0, 2), records=records,
                        exit_rays=records, record_rays=records)
    d = np.array([[0.0], [0.0], [-1.0]])
    scatter(MaterialTable.from_materials((glass,)), np.zeros(1, np.int64), d, -d,
            [np.full(1, 0.5)] * 4, pol=np.array([[1.0], [0.0], [0.0]]))
    # the map's filter, adaptive and sharpened, on a map with a bright patch (its tables
    # read-only, as runs read them)
    from ..film.pullpush import pull_push

    counts = np.random.default_rng(0).poisson(50.0, (6 * 8, 8)).astype(np.int64)
    counts[:4, :4] += 2000
    pull_push(counts * 1e-3, counts, 100.0)
    # a batch's escapes added to (and taken out of) an emitter's goniophotometer counts
    cells = np.zeros((2, 4), np.int64)
    for sign in (1, -1):
        compiled.add_bins(cells.reshape(-1), np.array([1, 5, 5], np.int64), sign)


def _type_spec(t) -> list | str:
    """A numba argument type as :func:`lumitrace.trace.compiled._check` reads it."""
    from numba.core import types

    if isinstance(t, types.Array):
        return ["array", str(np.dtype(str(t.dtype))), t.ndim, t.layout, t.mutable]
    if isinstance(t, (types.Integer, types.Float, types.Boolean)):
        name = "bool" if isinstance(t, types.Boolean) else str(t)
        if name in compiled._SCALARS:
            return name
    raise TypeError(f"a kernel argument of type {t} cannot be built ahead of time")


def build(directory: Path | None = None, force: bool = False) -> Path:
    """Build the kernels for the current sources (unless built already) and return the
    extension module's path; older builds in the same folder are removed."""
    import numba.pycc.compiler as pycc_compiler
    from numba.core import codegen
    from numba.pycc import CC

    from . import kernels

    so, types_path = compiled.build_paths(directory)
    if so.exists() and types_path.exists() and not force:
        return so
    for name in compiled.ENTRY_POINTS:  # warm up through the JIT, even beside a build
        getattr(compiled, name).built = []
    warm_up()

    class _Flags(pycc_compiler.Flags):
        """The JIT's options (``kernels._JIT``) for the exported functions."""

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.release_gil = True
            self.error_model = "numpy"

    pycc_compiler.Flags = _Flags
    # this CPU's model and features, as the JIT targets them (pycc's default is the
    # architecture's baseline); the build's name says which CPU (compiled.cpu_key)
    codegen.AOTCPUCodegen._customize_tm_features = codegen.CPUCodegen._get_host_cpu_features
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pycc's pending-deprecation notice
        cc = CC(compiled.MODULE)
    cc.output_dir = str(so.parent)
    cc.target_cpu = "host"
    table: dict = {}
    for name in compiled.ENTRY_POINTS:
        dispatcher = getattr(kernels, name)
        for i, sig in enumerate(dispatcher.signatures):
            export = f"{name}_{i}"
            cc.export(export, dispatcher.overloads[sig].signature)(dispatcher.py_func)
            table.setdefault(name, []).append([export, [_type_spec(t) for t in sig]])
    so.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=so.parent) as tmp:
        cc.output_dir = tmp
        cc.output_file = so.name
        cc.compile()
        for old in so.parent.glob(compiled.MODULE + "-*"):
            old.unlink()
        Path(tmp, so.name).replace(so)
    types_path.write_text(json.dumps(table))
    return so


def main() -> int:
    try:
        path = build(force="--force" in sys.argv)
    except Exception as exc:  # no C compiler, no write access: the JIT serves
        print(f"note: the photon kernels were not built ahead of time ({exc}); "
              "they are compiled on first use instead", file=sys.stderr)
        return 0
    print(f"photon kernels built ahead of time: {path.name}")
    return 0


if __name__ == "__main__":  # pragma: no cover - python -m lumitrace.trace.aot
    sys.exit(main())
