"""numba's options for the photon kernels, and their on-disk cache keyed on all kernel
sources.

numba keys each cached function on its own file only: a caller in one module would keep
its cached machine code, with an old copy of a helper from another module inlined, after
that helper changed. The cache locators registered here give every function in this
package one stamp, :func:`lumitrace.trace.kernel_sources.digest`, so an edit of any kernel
file (or of the constants they compile in) recompiles them all. Where numba's cache
machinery is not what this expects, the kernels are not cached at all (slower to start,
never stale).
"""
from __future__ import annotations

import functools
from pathlib import Path

from ..kernel_sources import HERE, digest

_FOLDER = Path(__file__).resolve().parent


@functools.lru_cache(maxsize=None)
def _stamp() -> str:
    """The kernels' sources' digest, read once a process."""
    return digest(HERE)


def _register() -> bool:
    """Put locators with the shared stamp ahead of numba's own, for this folder's files:
    numba's own choice of place (``NUMBA_CACHE_DIR``, ``__pycache__``, the user's cache)."""
    try:
        from numba.core import caching

        bases = (caching.UserProvidedCacheLocator, caching.InTreeCacheLocator,
                 caching.UserWideCacheLocator)
        impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl")
        classes = impl._locator_classes
    except (ImportError, AttributeError):
        return False

    class _AllSources:
        def get_source_stamp(self):
            return _stamp()

        @classmethod
        def from_function(cls, py_func, py_file):
            if Path(py_file).resolve().parent != _FOLDER:
                return None
            return super().from_function(py_func, py_file)

    ours = [type(f"Kernel{b.__name__}", (_AllSources, b), {}) for b in bases]
    if not any(c.__name__ == ours[0].__name__ for c in classes):
        classes[:0] = ours
    return True


_JIT = dict(nogil=True, cache=_register(), error_model="numpy")
_INLINE = _JIT  # small helpers: LLVM inlines them
_ALWAYS = dict(_JIT, inline="always")  # large helpers on the hot path, inlined by numba
