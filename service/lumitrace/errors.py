"""Errors and warnings that name what is wrong and where: the prim, the property, the file.

Every warning lumitrace gives is a :class:`LumitraceWarning` sent with :func:`warn`, the one
route by which the command line prints them and the service turns them into events; the
stage reader also keeps its own in ``Scene.warnings`` (the scene's record of its input).
"""
from __future__ import annotations

import warnings


class LumitraceError(Exception):
    """A user-facing error: one clear sentence, no traceback needed.

    ``where`` is the prim path, property or file the problem lives in; it leads the message
    so that a user (or the service's 4xx body) sees at once what to fix.
    """

    def __init__(self, message: str, where: str | None = None, prop: str | None = None):
        self.message = message
        self.where = where
        self.prop = prop
        super().__init__(self.__str__())

    def __str__(self) -> str:
        loc = self.where or ""
        if self.prop:
            loc = f"{loc}.{self.prop}" if loc else self.prop
        return f"{loc}: {self.message}" if loc else self.message


class StageError(LumitraceError):
    """The stage cannot be read into a scene (missing file, bad value, unknown token)."""


class OutputError(LumitraceError):
    """A result could not be written (nothing half-written is left behind)."""


class ClusterLost(LumitraceError):
    """The Dask scheduler went away mid-run (:mod:`lumitrace.run.cluster`); ``tallies``
    are the round's batch tallies (:class:`~lumitrace.film.tally.BatchTally`) gathered
    before it did (a prefix of the round's jobs, in job order)."""

    #: the command line's exit status for it: the outputs hold the batches that finished
    exit_status = 4

    def __init__(self, message: str, where: str, tallies: list):
        super().__init__(message, where)
        self.tallies = tallies
        self.result = None  # the session's result of the batches that finished

    def written(self, photons: int) -> "ClusterLost":
        """This error, saying that the outputs of ``photons`` photons were written."""
        self.message += (f" after {photons:,} photons: the outputs hold the batches that "
                         "finished")
        return self


class Interrupted(BaseException):
    """SIGINT, SIGTERM or SIGHUP arrived; ``published`` says whether this run's outputs
    were already complete on disk when it did (a BaseException, like KeyboardInterrupt,
    so that no ``except Exception`` swallows it)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum
        self.published = False


class LumitraceWarning(UserWarning):
    """Something the user should know, with a result all the same."""


class OutputWarning(LumitraceWarning):
    """An output was written differently than asked (a picture skipped, a layer not
    sublayered), with the reason."""


def warn(message: str, category: type[LumitraceWarning] = LumitraceWarning) -> None:
    """Send a lumitrace warning (shown once per distinct message by Python's defaults)."""
    warnings.warn(message, category, stacklevel=3)
