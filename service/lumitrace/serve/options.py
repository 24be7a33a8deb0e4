"""The options of ``lumitrace serve`` that say who may reach the service and how much work
a client may ask for (see docs/service-security.md): standard library only, read when the
command line is built."""
from __future__ import annotations

from pathlib import Path


def add_access_options(parser, positive_int, positive_float) -> None:
    """``--token``/``--token-file``, ``--allow-host``, ``--max-photons`` and
    ``--min-target-error`` on the serve command's ``parser`` (``positive_int`` and
    ``positive_float``: the command line's checks of those numbers)."""
    token = parser.add_mutually_exclusive_group()
    token.add_argument("--token", help="bearer token every request must carry (shown in the "
                       "process list: prefer --token-file or env LUMITRACE_TOKEN)")
    token.add_argument("--token-file", type=Path, metavar="FILE",
                       help="read the bearer token from FILE's first line")
    parser.add_argument("--allow-host", action="append", default=[], metavar="NAME",
                        help="a name requests may give as Host besides localhost, loopback "
                             "addresses and --host (repeatable)")
    parser.add_argument("--max-photons", type=positive_int, metavar="N",
                        help="the largest photon budget a client may set (default 1e10)")
    parser.add_argument("--min-target-error", type=positive_float, metavar="E",
                        help="the smallest target error a client may set (default 0.002)")
