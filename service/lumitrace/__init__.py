"""lumitrace: far-field luminous intensity of OpenUSD luminaires by photon tracing.

Importing the package registers the lumitrace USD schema plugin, so it must happen before
any stage is composed (late registration is silently ignored by USD).
"""
import _signal  # the interpreter's built-in: the recorders below import nothing first
import sys as _sys

#: Signals received while ``python -m lumitrace`` loads the package (USD takes a few
#: tenths of a second and can swallow a KeyboardInterrupt): recorded from the package's
#: first statement and handed to the command line by ``__main__``, as the ``lumitrace``
#: entry point does for its own start.
EARLY_SIGNALS: list[int] = []
if _sys.argv[:1] == ["-m"]:  # being imported to run as ``python -m lumitrace``
    for _s in (_signal.SIGINT, _signal.SIGTERM, _signal.SIGHUP):
        _signal.signal(_s, lambda signum, _frame: EARLY_SIGNALS.append(signum))

import time as _time  # noqa: E402

#: When this process started lumitrace (``time.perf_counter``): ``trace --time`` counts
#: from here, so loading and reading the stage are part of the time asked for.
STARTED = _time.perf_counter()

from .schema import register_schema  # noqa: E402  (after the signal recorders)

register_schema()

__version__ = "0.1.0"
