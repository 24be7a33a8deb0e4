"""Exact comparison of traced tallies."""
import numpy as np

from lumitrace.film.accumulate import EscapeBins


def same_tally(a, b, where="tally"):
    """Exact equality of two tallies, field by field, arrays bit for bit (escape bins by
    the counts they make: the paths may write their escapes in another order)."""
    if isinstance(a, EscapeBins):
        assert isinstance(b, EscapeBins) and a.n == b.n, where
        assert np.array_equal(np.asarray(a), np.asarray(b)), where
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype, where
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), where
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            same_tally(x, y, f"{where}[{i}]")
    elif hasattr(a, "__slots__") or hasattr(a, "__dict__"):
        names = getattr(a, "__slots__", None) or vars(a)
        for name in names:
            same_tally(getattr(a, name), getattr(b, name), f"{where}.{name}")
    else:
        assert a == b, where
