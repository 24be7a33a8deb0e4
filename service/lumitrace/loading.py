"""Modules loaded with the cyclic garbage collector paused.

A module's objects (its functions, classes, constants; USD's wrapped types) live as long
as the process, so the collections that loading them sets off find no garbage: loading
USD and the trace command's modules after start-up set off some 40 collections, about
7 ms of a short run. Loaded with the collector paused, their objects are then frozen
(left out of later collections) and it resumes.
"""
from __future__ import annotations

import contextlib
import gc
from typing import Iterator


@contextlib.contextmanager
def collector_paused() -> Iterator[None]:
    """Pause the cyclic collector while the block loads modules; then freeze what exists
    and resume it (as it was: a block inside another pause leaves it paused)."""
    running = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if running:
            gc.freeze()
            gc.enable()
