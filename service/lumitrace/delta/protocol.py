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
#: Most values a request's deltas may hold in arrays, all deltas together (the numbers of a
#: mesh's points: 349,525 points of 3): beyond it the batch is refused (422) before it is
#: checked or applied, so that no one request holds the service for long (one of this
#: size applies in about 2 s, on the thread that edits the stage, not the event loop).
MAX_ARRAY_VALUES = 1 << 20
#: Arrays holding more values than this are checked against the schema's ``value``
#: definition by :func:`_value_problems` instead of the (much slower) validator.
_FAST_CHECK_VALUES = 256
#: Most items of one array (the schema's ``maxItems`` of ``value``).
_MAX_ITEMS = 1_000_000


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


def _value_slots(body: Any):
    """Each place in a request that holds a delta's ``value`` (a ``set``'s value, an
    ``add``'s property values): yields (JSON pointer, delta index, property name or None
    for a ``set``'s value, the value)."""
    deltas = body.get("deltas") if isinstance(body, dict) else None
    if not isinstance(deltas, list):
        return
    for i, delta in enumerate(deltas):
        if not isinstance(delta, dict):
            continue
        if "value" in delta:
            yield f"/deltas/{i}/value", i, None, delta["value"]
        props = delta.get("properties")
        if isinstance(props, dict):
            for name, value in props.items():
                yield f"/deltas/{i}/properties/{name}", i, name, value


def _array_values(value: Any) -> int:
    """How many values (leaves) the arrays of ``value`` hold; 0 for a scalar. Iterative:
    no nesting can exhaust the stack."""
    if not isinstance(value, list):
        return 0
    count, stack = 0, [value]
    while stack:
        items = stack.pop()
        for item in items:
            if isinstance(item, list):
                stack.append(item)
            else:
                count += 1
    return count


def _value_problems(value: Any, where: str) -> list[Problem]:
    """What the schema's ``value`` definition says of ``value`` (a number, boolean or string,
    or an array of at most a million of them, nested), found without the validator: it
    takes seconds over a mesh's points."""
    stack = [(value, where)]
    while stack:
        item, at = stack.pop()
        if isinstance(item, list):
            if len(item) > _MAX_ITEMS:
                return [Problem(at, f"array of {len(item)} items is too long (at most "
                                    f"{_MAX_ITEMS})")]
            stack.extend((v, f"{at}/{k}") for k, v in enumerate(item)
                         if not isinstance(v, (int, float, str)))  # bool is an int
        elif not isinstance(item, (int, float, str)):
            return [Problem(at, f"{json.dumps(item)[:80]} is not valid under any of the "
                                "given schemas")]
    return []


def _skeleton(body: Any) -> tuple[Any, list[Problem]]:
    """The request with every large array value replaced by 0 for the validator, and the
    problems :func:`_value_problems` found in those arrays. Raises :class:`DeltaError`
    (422) when the arrays hold more than :data:`MAX_ARRAY_VALUES` values in all."""
    slots = list(_value_slots(body))
    sizes = [_array_values(value) for *_, value in slots]
    if sum(sizes) > MAX_ARRAY_VALUES:
        raise DeltaError([Problem("/deltas", f"the deltas hold {sum(sizes)} array values, "
                                  f"more than the limit of {MAX_ARRAY_VALUES} array values "
                                  f"a request ({MAX_ARRAY_VALUES // 3} points of 3); send "
                                  "them in several requests")], 422)
    big = [slot for slot, n in zip(slots, sizes) if n > _FAST_CHECK_VALUES]
    if not big:
        return body, []
    problems = [p for where, _, _, value in big for p in _value_problems(value, where)]
    deltas = [dict(d) if isinstance(d, dict) else d for d in body["deltas"]]
    for _, i, name, _ in big:
        if name is None:
            deltas[i]["value"] = 0
        else:
            deltas[i]["properties"] = {**deltas[i]["properties"], name: 0}
    return {**body, "deltas": deltas}, problems


def check_request(body: Any) -> dict[str, Any]:
    """Validate a decoded request body against the schema; raise :class:`DeltaError` (422)
    listing every violation, ordered by where it is. Large arrays are counted first (at
    most :data:`MAX_ARRAY_VALUES` values) and checked without the validator."""
    checked, fast = _skeleton(body)
    errors = sorted(_validator().iter_errors(checked), key=lambda e: list(map(str, e.path)))
    if not errors and not fast:
        return body
    problems, seen = list(fast), set(fast)
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
