"""Exact comparison of traced tallies."""
import numpy as np


def same_tally(a, b, where="tally"):
    """Exact equality of two tallies, field by field, arrays bit for bit."""
    if isinstance(a, np.ndarray):
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
