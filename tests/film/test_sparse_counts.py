"""Accumulators of many emitters keep each emitter's nonzero texels only: exactly the same
maps, fluxes, variances and exact batch removal as the dense counts, in memory that follows
the photons rather than emitters x texels."""
import numpy as np
import pytest
from helpers.paths import ROOT

from lumitrace.film import accumulate
from lumitrace.film.accumulate import Accumulator, SparseCounts, compact
from lumitrace.stage.reader import read_stage
from lumitrace.trace.tracer import BatchJob, prepare, trace_batch


@pytest.fixture(scope="module")
def batches():
    scene = read_stage(ROOT / "stages" / "downlight.usda")
    ps = prepare(scene)
    return scene, [trace_batch(ps, BatchJob(0, first, n, 7, 16))
                   for first, n in ((0, 5000), (5000, 40), (5040, 20_000))]


def test_sparse_and_dense_accumulators_agree_exactly(batches, monkeypatch):
    scene, tallies = batches
    dense = Accumulator(scene, 16)
    monkeypatch.setattr(accumulate, "DENSE_COUNTS_BYTES", 0)
    sparse = Accumulator(scene, 16)
    assert isinstance(sparse.emitters[0].counts, SparseCounts)
    for t in tallies:
        dense.add(t)
        sparse.add(t)
    for half in (None, 0, 1):
        assert np.array_equal(dense.counts(half), sparse.counts(half))
        assert np.array_equal(dense.texel_flux(half), sparse.texel_flux(half))
    assert np.array_equal(dense.flux_variance(), sparse.flux_variance())
    assert dense.fluxes() == sparse.fluxes()
    # exact removal; a batch that cannot have been added is refused
    snap = sparse.snapshot()
    sparse.remove(tallies[1])
    dense.remove(tallies[1])
    assert np.array_equal(dense.counts(), sparse.counts())
    assert snap.photons == 25_040 and sparse.photons == 25_000
    sparse.remove(tallies[0])
    sparse.remove(tallies[2])
    assert sparse.photons == 0 and len(sparse.emitters[0].counts.idx) == 0
    with pytest.raises(ValueError):
        sparse.remove(tallies[1])


def test_a_compact_batch_adds_like_the_dense_one(batches):
    scene, tallies = batches
    small = tallies[1]  # 40 photons in 1536 texels
    packed = compact(small.counts)
    assert isinstance(packed, SparseCounts) and len(packed.idx) <= 40
    assert np.array_equal(packed.dense(), small.counts)
    a, b = Accumulator(scene, 16), Accumulator(scene, 16)
    a.add(small)
    b.add(type(small)(small.emitter, small.start, small.photons, packed, small.absorbed,
                      small.cut, small.segments))
    assert np.array_equal(a.counts(), b.counts())
    assert compact(tallies[2].counts) is tallies[2].counts  # dense where dense is smaller


def test_a_batch_that_could_fill_a_quarter_of_the_bins_stays_dense_unlooked(batches):
    """Told the batch's photons, compact keeps a large batch's counts as they are (no scan),
    and still packs a small batch's; the packed counts are the same counts."""
    _, tallies = batches
    big, small = tallies[2], tallies[1]  # 20,000 and 40 photons in 2 x 1536 texels
    assert compact(big.counts, big.photons) is big.counts
    narrow = np.zeros_like(big.counts)
    narrow[0, 3] = big.photons  # every photon in one texel: kept dense, as its size allows
    assert compact(narrow, big.photons) is narrow
    assert isinstance(compact(narrow), SparseCounts)  # looked at, it packs
    packed = compact(small.counts, small.photons)
    assert isinstance(packed, SparseCounts) and np.array_equal(packed.dense(), small.counts)
