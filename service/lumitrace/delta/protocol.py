"""The scene-delta protocol: the JSON Schema in ``schemas/scene-delta.schema.json`` checked
with a real validator, every problem listed with where it is and why."""
from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from ..errors import LumitraceError
from ..schema import SCHEMA_DIR

#: The protocol's JSON Schema (draft 2020-12).
DELTA_SCHEMA_PATH = SCHEMA_DIR / "scene-delta.schema.json"
#: Deepest nesting of arrays and objects a request may have (a delta needs five levels:
#: a matrix in a delta in the list in the body); deeper is refused before it is checked.
MAX_DEPTH = 32


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a request: ``where`` (a JSON pointer into the body, or a prim
    path and property) and ``why``."""

    where: str
    why: str

    def as_dict(self) -> dict[str, str]:
        return {"where": self.where, "why": self.why}


class DeltaError(LumitraceError):
    """A batch of deltas refused as a whole (nothing of it applied); ``problems`` lists every
    problem found, ``status`` is the HTTP status to answer with."""

    def __init__(self, problems: list[Problem], status: int = 422):
        self.problems = list(problems)
        self.status = status
        first = self.problems[0] if self.problems else Problem("", "refused")
        more = f" (and {len(self.problems) - 1} more)" if len(self.problems) > 1 else ""
        super().__init__(first.why + more, first.where or None)


@lru_cache(maxsize=1)
def delta_schema() -> dict[str, Any]:
    """The protocol's JSON Schema, read once."""
    return json.loads(DELTA_SCHEMA_PATH.read_text(encoding="utf-8"))


@lru_cache(maxsize=1)
def _validator():
    from jsonschema import Draft202012Validator

    schema = delta_schema()
    Draft202012Validator.check_schema(schema)
    return Draft202012Validator(schema)


def _pointer(path) -> str:
    return "/" + "/".join(str(p) for p in path) if path else "/"


def _leaf_errors(error):
    """The most specific errors under a schema error (``if/then`` and ``anyOf`` branches
    report on their own; their wrappers only say that a branch failed)."""
    if error.context:
        for sub in error.context:
            yield from _leaf_errors(sub)
    else:
        yield error


def check_request(body: Any) -> dict[str, Any]:
    """Validate a decoded request body against the schema; raise :class:`DeltaError` (422)
    listing every violation, ordered by where it is."""
    errors = sorted(_validator().iter_errors(body), key=lambda e: list(map(str, e.path)))
    if not errors:
        return body
    problems, seen = [], set()
    for error in errors:
        for leaf in _leaf_errors(error):
            p = Problem(_pointer(leaf.absolute_path), leaf.message[:300])
            if p not in seen:
                seen.add(p)
                problems.append(p)
    raise DeltaError(problems, 422)


class _NotJson(ValueError):
    pass


def _not_json(constant: str):
    raise _NotJson(constant)


def parse_request(raw: bytes) -> dict[str, Any]:
    """Decode and validate a request body (UTF-8 JSON); 400 for what is not JSON at all."""
    return check_request(_decode(raw))


def parse_json_object(raw: bytes) -> dict[str, Any]:
    """Decode a request body that must be one JSON object (the session's settings), with
    the same checks of encoding, numbers, depth and NUL characters as a delta's."""
    body = _decode(raw)
    if not isinstance(body, dict):
        raise DeltaError([Problem("/", f"body must be a JSON object, got "
                                       f"{type(body).__name__}")], 400)
    return body


def _decode(raw: bytes) -> Any:
    """A request body's JSON value, checked by :func:`check_shape`."""
    try:
        body = json.loads(raw.decode("utf-8"), parse_constant=_not_json)
    except UnicodeDecodeError as exc:
        raise DeltaError([Problem("/", f"body is not UTF-8: {exc.reason} at byte "
                                       f"{exc.start}")], 400) from None
    except _NotJson as exc:
        raise DeltaError([Problem("/", f"body is not JSON: {exc} is not a JSON value (JSON "
                                       "numbers are finite)")], 400) from None
    except json.JSONDecodeError as exc:
        raise DeltaError([Problem("/", f"body is not JSON: {exc.msg} at line {exc.lineno} "
                                       f"column {exc.colno}")], 400) from None
    except RecursionError:
        raise DeltaError([Problem("/", f"body is nested too deeply (more than {MAX_DEPTH} "
                                       "levels of arrays and objects)")], 400) from None
    check_shape(body)
    return body


def check_shape(body: Any) -> None:
    """Refuse what no schema check should see: nesting deeper than :data:`MAX_DEPTH`
    (400), and text holding a NUL character (422: USD would cut the text short there).
    Walked without recursion, so that no depth can exhaust the stack."""
    stack: list[tuple[Any, tuple, int]] = [(body, (), 1)]
    nul: list[Problem] = []
    while stack:
        value, path, depth = stack.pop()
        if isinstance(value, (list, dict)):
            if depth > MAX_DEPTH:
                raise DeltaError([Problem(_pointer(path), f"body is nested too deeply "
                                          f"(more than {MAX_DEPTH} levels of arrays and "
                                          "objects)")], 400)
            items = value.items() if isinstance(value, dict) else enumerate(value)
            for key, item in items:
                if isinstance(key, str) and "\x00" in key:
                    nul.append(Problem(_pointer(path), f"name {key!r} contains a NUL "
                                                       "character"))
                if isinstance(item, (list, dict, str)):
                    stack.append((item, path + (key,), depth + 1))
        elif isinstance(value, str) and "\x00" in value:
            nul.append(Problem(_pointer(path), f"text {value[:80]!r} contains a NUL "
                                               "character"))
    if nul:
        raise DeltaError(sorted(nul, key=lambda p: p.where), 422)
