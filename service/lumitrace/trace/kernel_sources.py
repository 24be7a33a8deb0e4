"""The files the compiled photon kernels are made of, and one digest of them: what numba's
on-disk cache (:mod:`lumitrace.trace.kernels.jit`) and the ahead-of-time build
(:mod:`lumitrace.trace.compiled`) are keyed on, so an edit of any of them rebuilds both."""
from __future__ import annotations

import hashlib
from pathlib import Path

#: The kernels' modules and the constants they compile in (relative to this folder).
SOURCES = ("kernels/__init__.py", "kernels/jit.py", "kernels/maths.py",
           "kernels/scattering.py", "kernels/binning.py", "kernels/emission.py",
           "kernels/paths.py", "kernels/filtering.py", "codes.py", "rng.py", "records.py")
HERE = Path(__file__).resolve().parent


def digest(here: Path = HERE) -> str:
    """sha256 (hex) of every source's name and text under ``here`` and of the material
    codes (:mod:`lumitrace.scene.model`) the kernels compare against."""
    from ..scene import model

    h = hashlib.sha256()
    for name in SOURCES:
        h.update(name.encode() + b"\0" + (here / name).read_bytes())
    codes = sorted((k, v) for k, v in vars(model).items() if k.isupper() and isinstance(v, int))
    h.update(repr(codes).encode())
    return h.hexdigest()
