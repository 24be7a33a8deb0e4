"""A batch's goniophotometer counts travel as its escapes' bins and are added where they
fall: the same counts as the dense tally they replace, into dense or sparse accumulators,
exactly removable, compiled or not, and the same after pickling."""
import pickle

import numpy as np
import pytest

from lumitrace.film import accumulate
from lumitrace.film.accumulate import EscapeBins, SparseCounts, _add_counts, counts_of
from lumitrace.trace import compiled  # noqa: F401  (loads the compiled scatter)

N = 5000


@pytest.fixture
def bins():
    rng = np.random.default_rng(3)
    b = rng.integers(0, 2 * N, 20_000)
    return np.concatenate([b, np.full(500, 17), np.full(300, N + 17)])  # one bin often


def test_escape_bins_add_the_counts_they_stand_for(bins):
    want = counts_of(bins, N)
    assert isinstance(want, np.ndarray) and want.sum() == bins.size
    dense = np.zeros((2, N), np.int64)
    _add_counts(dense, EscapeBins(N, bins), 1)
    assert np.array_equal(dense, want)
    assert np.array_equal(np.asarray(EscapeBins(N, bins)), want)
    assert dense[0, 17] >= 500 and dense[1, 17] >= 300
    # exactly out again, compiled and with numpy's scatter alike
    _add_counts(dense, EscapeBins(N, bins), -1)
    assert not dense.any()
    assert accumulate._scatter is not accumulate._scatter_numpy
    plain = np.zeros((2, N), np.int64)
    accumulate._scatter_numpy(plain.reshape(-1), bins, 1)
    assert np.array_equal(plain, want)


def test_escape_bins_go_into_sparse_and_strided_counts_alike(bins):
    want = counts_of(bins, N)
    sparse = SparseCounts(N)
    _add_counts(sparse, EscapeBins(N, bins[:50]), 1)
    _add_counts(sparse, EscapeBins(N, bins[50:]), 1)
    assert np.array_equal(sparse.dense(), want)
    wide = np.zeros((2, 2 * N), np.int64)
    view = wide[:, ::2]  # not contiguous: no flat view to scatter into
    _add_counts(view, EscapeBins(N, bins), 1)
    assert np.array_equal(view, want) and wide.sum() == bins.size


def test_escape_bins_pickle_and_stay_compact(bins):
    e = EscapeBins(N, bins)
    back = pickle.loads(pickle.dumps(e))
    assert isinstance(back, EscapeBins) and back.n == N
    assert np.array_equal(back.bins, bins)
    assert accumulate.compact(e, 10) is e
