"""Errors that name what is wrong and where: the prim, the property, the file."""
from __future__ import annotations


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
