"""The compiled photon work: emission, scattering, binning and the path loop, without the
GIL.

Between two Embree calls a photon needs a few hundred floating-point operations; done as
numpy array passes that cost more than the intersection itself (temporaries, gathers,
page faults). Here photons are handled in loops compiled by numba that call Embree
themselves: each photon is followed from its emission to its escape, absorption or cut,
four at a time, their rays cast together as a packet (``rtcIntersect4``: a fifth less
time per ray than one at a time, the same hits). An escape is binned into the cube map, the
goniophotometer's cell and exit bin (and the photon's record, when kept); a hit is offset
and scattered by its material's model. The same loop can instead advance a wave of
photons by one bounce, from Embree's hits of a batch of rays (for embreex).

The modules by job: :mod:`.maths` (random numbers, vectors), :mod:`.emission`,
:mod:`.scattering`, :mod:`.binning` and :mod:`.paths` (the loop); beside them the map's
filter, :mod:`.filtering` (the pull-push's push step, built with them); numba's disk cache is
keyed on all of them (:mod:`.jit`). Per photon the arithmetic is scalar float64, the same
for any wave size, batch size or thread, so maps stay bit-identical across them.
"""
from __future__ import annotations

from .binning import (_CHUNK, _acos_fast, _atan2_fast, _gonio_cell_exact, add_bins,
                      gonio_bins, texels)
from .emission import cull, emit_photons, start
from .filtering import push_level
from .maths import _turn, _uniform_pair
from .paths import bounce, intersect, pair_quads
from .scattering import scatter_many, scatter_one

__all__ = ["start", "cull", "bounce", "emit_photons", "scatter_many", "intersect",
           "push_level", "pair_quads", "add_bins", "texels",
           "gonio_bins", "scatter_one", "_CHUNK", "_acos_fast", "_atan2_fast",
           "_gonio_cell_exact", "_turn", "_uniform_pair"]
