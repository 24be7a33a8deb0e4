"""Integer codes the compiled kernels (:mod:`lumitrace.trace.kernels`) and their callers
share, kept apart from them so that callers need not load the compiler to name them."""
from __future__ import annotations

#: Emitter shapes as :func:`~lumitrace.trace.kernels.emit_photons` takes them.
DISK, RECT, SPHERE, CYLINDER, MESH, RAYS = 0, 1, 2, 3, 4, 5

#: A photon's spectral state besides a band number (see :mod:`lumitrace.trace.kernels`):
#: throughput 1 in every band, nothing coloured met yet (its row not written), or a
#: throughput row of its own.
PRISTINE, MIXED = -1, -2
