"""Who may talk to the service: each request's ``Host``, ``Origin`` (or ``Sec-Fetch-Site``),
``Content-Type`` and the live view's per-process key, checked before any handler runs.

A web page the designer opens anywhere can make the browser send requests to a server on
loopback: "simple" cross-origin POSTs (a form, ``fetch`` in no-cors mode, a beacon) that
need no preflight, and, through DNS rebinding, same-origin requests under the attacker's
own name. The rules, as the best local development servers have them:

* ``Host`` names this service: a loopback name or address, the address it is bound to,
  or a name given with ``--allow-host``; anything else is a 421 (a rebinding page's
  requests carry its own name).
* A browser's request (it carries ``Origin`` or ``Sec-Fetch-*``) comes from the service's
  own origin, or from the user's own navigation (``Sec-Fetch-Site: none``): 403 otherwise.
  The page's files (``/``, ``/page/...``) may be opened from anywhere: they hold no data
  and no other origin can read them.
* A request that changes state sends JSON (``Content-Type: application/json``, which no
  page can send to another origin without a CORS preflight, never granted here): 415
  otherwise. From a browser it also carries the page's key (``X-Lumitrace-Key``), given
  only in the page itself: a forged request fails even where a browser sends no
  ``Origin``.

A program's request (the stdlib client, a DCC's Python, curl) carries neither ``Origin``
nor ``Sec-Fetch-*``: it needs no key. With ``--token`` every request but the page's files
also needs ``Authorization: Bearer TOKEN`` (401), checked after the origin and before the
body.
"""
from __future__ import annotations

import hmac
import ipaddress
import os
import re
import secrets
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

from ..errors import LumitraceError, warn

#: Host names that always mean this machine (loopback addresses are taken as addresses).
LOOPBACK_NAMES = frozenset({"localhost"})
#: The header in which the live view sends its per-process key.
KEY_HEADER = "X-Lumitrace-Key"
#: Methods that change nothing.
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
#: ``Sec-Fetch-Site`` of a request made by the service's own page or typed by the user.
OWN_SITES = frozenset({"same-origin", "none"})
#: Addresses meaning "every interface": any address literal of the machine names it then.
WILDCARDS = frozenset({"", "0.0.0.0", "::"})


@dataclass(frozen=True)
class Refusal:
    """Why a request is refused: its HTTP status and one sentence."""

    status: int
    message: str


def split_host(value: str) -> tuple[str, int | None] | None:
    """(name or address, port) of a ``Host`` header or an origin's authority: lower-case,
    without brackets or a final dot; None where it is malformed."""
    value = value.strip().lower()
    if value.startswith("["):
        name, sep, rest = value[1:].partition("]")
        if not sep or (rest and not rest.startswith(":")):
            return None
        port = rest[1:] if rest else None
    else:
        name, sep, port = value.partition(":")
        if sep and not port:
            return None
        port = port or None
    if port is not None and not (port.isdigit() and int(port) <= 65535):
        return None
    name = name[:-1] if name.endswith(".") else name
    if not name or any(c.isspace() or c in "/\\@?#" for c in name):
        return None
    return name, int(port) if port is not None else None


def header_bytes(value: str) -> bytes:
    """A header's value as the bytes the client sent: what is not UTF-8 (Latin-1, say)
    arrives as surrogate escapes, which a plain ``encode`` refuses (a 500 for a wrong
    token or key)."""
    try:
        return value.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:  # a lone surrogate no client byte maps to
        return value.encode("utf-8", "surrogatepass")


def _address(name: str):
    try:
        return ipaddress.ip_address(name.split("%", 1)[0])
    except ValueError:
        return None


@dataclass(frozen=True)
class Guard:
    """The rules of one service: ``bound`` is the address (or name) it listens on,
    ``allowed`` the extra host names (``--allow-host``), ``token`` the bearer token (None:
    none needed); ``key`` is the page's secret, new for every process."""

    bound: str = "127.0.0.1"
    allowed: frozenset[str] = frozenset()
    token: str | None = field(default=None, repr=False)
    key: str = field(default_factory=lambda: secrets.token_urlsafe(32), repr=False)

    @classmethod
    def of(cls, bound: str, allow_hosts=(), token: str | None = None) -> "Guard":
        names = set()
        for given in allow_hosts:
            parts = split_host(given)
            if parts is None or parts[1] is not None:
                raise ValueError(f"--allow-host takes a host name or address without a "
                                 f"port, got {given!r}")
            names.add(parts[0])
        return cls(bound.strip("[]").lower(), frozenset(names), token)

    def host_allowed(self, name: str) -> bool:
        """Whether ``name`` (from :func:`split_host`) names this service."""
        if name in LOOPBACK_NAMES or name in self.allowed or name == self.bound:
            return True
        address = _address(name)
        if address is None:
            return False
        if address.is_loopback or self.bound in WILDCARDS:
            return True  # an address literal cannot be rebound to another machine
        return address == _address(self.bound)

    def check(self, method: str, headers, content_type: str,
              page_file: bool = False) -> Refusal | None:
        """The refusal of a request (its method, headers and parsed content type), None
        where it may go on; ``page_file``: a GET of the page's own files."""
        raw = headers.get("Host")
        host = split_host(raw) if raw is not None else None
        if host is None:
            return Refusal(400, "a request needs a valid Host header")
        if not self.host_allowed(host[0]):
            return Refusal(421, f"Host {raw!r} does not name this service (it answers to "
                                "localhost, loopback addresses and the address it is bound "
                                "to; give other names with --allow-host)")
        browser = "Origin" in headers or any(h.lower().startswith("sec-fetch-")
                                            for h in headers)
        if browser and not page_file:
            refusal = self._same_origin(headers, host)
            if refusal is not None:
                return refusal
        if self.token is not None and not page_file:
            given = header_bytes(headers.get("Authorization", ""))
            if not hmac.compare_digest(given, f"Bearer {self.token}".encode()):
                return Refusal(401, "missing or wrong bearer token (Authorization: Bearer "
                                    "TOKEN)")
        if method in SAFE_METHODS:
            return None
        if content_type != "application/json":
            return Refusal(415, f"a {method} request sends JSON (Content-Type: "
                                f"application/json), got {content_type or 'none'!r}")
        if browser:
            given = header_bytes(headers.get(KEY_HEADER, ""))
            if not hmac.compare_digest(given, self.key.encode()):
                return Refusal(403, f"a request from a web page needs the live view's key "
                                    f"({KEY_HEADER}), which only the service's own page has")
        return None

    @staticmethod
    def _same_origin(headers, host: tuple[str, int | None]) -> Refusal | None:
        """A browser's request from anywhere but the service's own origin, refused."""
        site = headers.get("Sec-Fetch-Site")
        if site is not None and site.lower() not in OWN_SITES:
            return Refusal(403, f"cross-origin request refused (Sec-Fetch-Site: {site})")
        origin = headers.get("Origin")
        if origin is None:
            return None
        # the same name and port as the Host the browser sent (https: through a TLS
        # proxy, whose name --allow-host gives)
        parts = urlsplit(origin.strip().lower())
        default = {"http": 80, "https": 443}.get(parts.scheme)
        theirs = split_host(parts.netloc) if default and parts.netloc else None
        if theirs is None or theirs[0] != host[0] or \
                (theirs[1] or default) != (host[1] or default):
            return Refusal(403, f"cross-origin request refused (Origin: {origin})")
        return None


def read_token(given: str | None, path: Path | None) -> str | None:
    """The service's bearer token: ``--token``, the first line of ``--token-file``, or
    the environment's ``LUMITRACE_TOKEN`` (None: no token); one a header can carry."""
    where = "--token"
    if path is not None:
        where = f"--token-file {path}"
        try:
            lines = Path(path).read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            why = getattr(exc, "strerror", None) or exc
            raise LumitraceError(f"cannot read the token: {why}", str(path)) from None
        given = lines[0].strip() if lines else ""
        if not given:
            raise LumitraceError("the token file is empty", str(path))
    elif given is None:
        given, where = os.environ.get("LUMITRACE_TOKEN") or None, "LUMITRACE_TOKEN"
    else:
        warn("--token is visible to every user of this machine in the process list: give "
             "it with --token-file FILE or the environment's LUMITRACE_TOKEN")
    if given is not None and not re.fullmatch(r"[\x21-\x7e]+", given):
        raise LumitraceError(f"{where}: a token is printable ASCII without spaces")
    return given
