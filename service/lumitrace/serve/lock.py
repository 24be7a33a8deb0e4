"""The stage's lock a service holds (see :mod:`lumitrace.delta.lock`: the edits commands
take the same lock)."""
from ..delta.lock import LOCK_SUFFIX, StageLock, lock_path

__all__ = ["LOCK_SUFFIX", "StageLock", "lock_path"]
