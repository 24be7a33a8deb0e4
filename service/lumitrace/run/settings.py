"""What to trace and when to stop: settings that check themselves, and every default once.

A JSON request to the service builds :class:`TraceSettings` as the command line does, so
the checks live here, not in argparse: a bad value is one :class:`SettingsError` naming
the setting, before anything is traced.
"""
from __future__ import annotations

import math
import numbers
import os
import re
from dataclasses import dataclass, field, replace

from ..errors import LumitraceError
from ..trace.job import MAX_DEPTH

#: Photons traced when no stop criterion is given.
DEFAULT_PHOTONS = 2_000_000
#: Cube-map face size in texels.
DEFAULT_RESOLUTION = 64
#: Photon count from which a texel trusts its own estimate whatever its neighbours say
#: (pull-push threshold): 1 / 0.01**2, the count at which its own noise is 1%. The
#: sharpened filter keeps lobes' shape, so it can lean on neighbours this long.
DEFAULT_THRESHOLD = 10000.0
#: Error below which a result counts as converged when no target is given.
DEFAULT_TARGET_ERROR = 0.02
#: Photons per batch job: a batch has fixed costs (its emission's set-up, its tallies'
#: arrays), so larger batches cost less a photon (2^18: 2.4% less CPU than 2^17 over a
#: 10M-photon run of the mirror cup, when each batch also counted a dense goniophotometer
#: tally of 3.4 MB; 2^19 another 0.9%, for 15 MB more and the threads' last batches less
#: even).
DEFAULT_BATCH_SIZE = 1 << 18
#: Tracing time (s) of a convergence report and of the benchmark when none is given.
DEFAULT_REPORT_SECONDS = 30.0
DEFAULT_BENCH_SECONDS = 10.0

#: Largest cube-map face size: 6 x 1024^2 texels, 100 MB of counts per accumulator.
MAX_RESOLUTION = 1024
#: Largest photon budget: photon indices stay far inside int64 and float64 sums exact.
MAX_PHOTONS = 1 << 53
#: Seeds are stored as 32-bit ints in the result layer (``lumitrace:result:seed``).
MAX_SEED = 2 ** 31 - 1
MAX_THREADS = 1024
MAX_TRACE_DEPTH = 1 << 20
WORKER_MODES = ("auto", "threads", "processes")
#: What a target error is judged on: the photometric files (their grid's relative RMS
#: standard error and worst lit value, the default: what the user ships) or the map.
TARGETS = ("files", "map")


class SettingsError(LumitraceError):
    """A trace setting is out of range or of the wrong type."""


#: The form of the Dask scheduler addresses lumitrace connects to (Dask's TCP comm).
SCHEDULER_FORM = "tcp://HOST:PORT"
_SCHEDULER = re.compile(r"tcp://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?)"
                        r":([0-9]{1,5})")
#: Why the schemes Dask knows but lumitrace does not connect to are refused.
_SCHEMES = {"tls": "needs TLS certificates, which lumitrace does not pass to Dask",
            "inproc": "is a scheduler inside one process, which no other process reaches",
            "ucx": "needs UCX, which lumitrace does not set up",
            "ws": "is Dask's websocket comm, which lumitrace does not set up",
            "wss": "is Dask's websocket comm, which lumitrace does not set up"}


def scheduler_problem(address) -> str | None:
    """Why ``address`` is no Dask scheduler address lumitrace connects to (the accepted
    form is :data:`SCHEDULER_FORM`: a host name, an IPv4 address or an [IPv6] address, and
    a port 1-65535), or None where it is one."""
    accepted = f"give the scheduler's address as {SCHEDULER_FORM}, e.g. tcp://127.0.0.1:8786"
    if not isinstance(address, str):
        return f"must be text, got {type(address).__name__}"
    scheme, sep, _ = address.partition("://")
    if not sep:
        return f"{address!r} has no scheme: {accepted}"
    if scheme in _SCHEMES:
        return f"{scheme}:// {_SCHEMES[scheme]}: {accepted}"
    if scheme != "tcp":
        return f"{scheme}:// is not a Dask scheduler's scheme: {accepted}"
    m = _SCHEDULER.fullmatch(address)
    if m is None or not 1 <= int(m.group(2)) <= 65535:
        return f"{address!r} is not a host and a port 1-65535: {accepted}"
    return None


def scheduler_address(text: str) -> str:
    """``--scheduler``'s argparse type: ``text`` where :func:`scheduler_problem` finds
    nothing wrong, else the parser's error (exit status 2, before anything runs)."""
    import argparse

    problem = scheduler_problem(text)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return text


def default_threads() -> int:
    """Tracing workers when none are asked for: all cores."""
    return os.cpu_count() or 1


def _integer(name: str, value, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or \
            not math.isfinite(value) or float(value) != int(value):
        raise SettingsError(f"must be an integer, got {value!r}", prop=name)
    v = int(value)
    if not lo <= v <= hi:
        raise SettingsError(f"must be between {lo:,} and {hi:,}, got {v:,}", prop=name)
    return v


def _real(name: str, value, lo: float, hi: float = math.inf, lo_open: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise SettingsError(f"must be a finite number, got {value!r}", prop=name)
    v = float(value)
    if v < lo or (lo_open and v == lo) or v > hi:
        bound = f"greater than {lo:g}" if lo_open else f"at least {lo:g}"
        limit = "" if hi == math.inf else f" and at most {hi:g}"
        raise SettingsError(f"must be {bound}{limit}, got {v:g}", prop=name)
    return v


@dataclass(frozen=True)
class TraceSettings:
    """What to trace and when to stop: ``photons`` (total), ``seconds`` or ``target_error``
    (relative error of the photometric files or, with ``target_of="map"``, of the written
    map); the first one reached stops the session, and with none given the session traces
    :data:`DEFAULT_PHOTONS`."""

    photons: int | None = None
    seconds: float | None = None
    target_error: float | None = None
    resolution: int = DEFAULT_RESOLUTION
    threshold: float = DEFAULT_THRESHOLD
    seed: int = 0
    threads: int = field(default_factory=default_threads)
    batch_size: int = DEFAULT_BATCH_SIZE
    max_depth: int = MAX_DEPTH
    workers: str = "auto"
    #: a Dask scheduler's address (tcp://HOST:PORT): batches run on its workers
    scheduler: str | None = None
    #: what ``target_error`` (and ``converged``) is judged on: one of :data:`TARGETS`
    target_of: str = "files"

    def __post_init__(self) -> None:
        put = lambda name, v: object.__setattr__(self, name, v)  # noqa: E731 (frozen)
        if self.photons is not None:
            put("photons", _integer("photons", self.photons, 1, MAX_PHOTONS))
        if self.seconds is not None:
            put("seconds", _real("seconds", self.seconds, 0.0, lo_open=True))
        if self.target_error is not None:
            put("target_error", _real("target_error", self.target_error, 0.0, 1.0,
                                      lo_open=True))
        put("resolution", _integer("resolution", self.resolution, 1, MAX_RESOLUTION))
        put("threshold", _real("threshold", self.threshold, 0.0))
        put("seed", _integer("seed", self.seed, 0, MAX_SEED))
        put("threads", _integer("threads", self.threads, 1, MAX_THREADS))
        put("batch_size", _integer("batch_size", self.batch_size, 1, 1 << 24))
        put("max_depth", _integer("max_depth", self.max_depth, 0, MAX_TRACE_DEPTH))
        if self.target_of not in TARGETS:
            raise SettingsError(f"must be one of {', '.join(TARGETS)}, got "
                                f"{self.target_of!r}", prop="target_of")
        if self.workers not in WORKER_MODES:
            raise SettingsError(f"must be one of {', '.join(WORKER_MODES)}, got "
                                f"{self.workers!r}", prop="workers")
        problem = None if self.scheduler is None else scheduler_problem(self.scheduler)
        if problem is not None:
            raise SettingsError(problem, prop="scheduler")

    def budget(self) -> int | None:
        """Total photons to trace, or None when only time or error stops the session."""
        if self.photons is None and self.seconds is None and self.target_error is None:
            return DEFAULT_PHOTONS
        return self.photons

    @property
    def convergence_target(self) -> float:
        """The error at or below which a result is converged."""
        return self.target_error or DEFAULT_TARGET_ERROR


#: The settings a service's client may change while it runs.
KNOBS = ("threshold", "target_error", "photons", "paused")
#: The largest photon budget and the smallest target error a service's client may ask
#: for by default (``serve --max-photons``, ``--min-target-error``): about half an hour of
#: tracing on a laptop's cores, and a grid error ten times below the default target.
SERVICE_MAX_PHOTONS = 10_000_000_000
SERVICE_MIN_TARGET_ERROR = 0.002


@dataclass(frozen=True)
class ServiceLimits:
    """The work a client of a service may ask for through ``/settings``, as the command
    line that started it allows: a photon budget of at most ``max_photons``, a target
    error of at least ``min_target_error``."""

    max_photons: int = SERVICE_MAX_PHOTONS
    min_target_error: float = SERVICE_MIN_TARGET_ERROR

    def __post_init__(self) -> None:
        put = lambda name, v: object.__setattr__(self, name, v)  # noqa: E731 (frozen)
        put("max_photons", _integer("max_photons", self.max_photons, 1, MAX_PHOTONS))
        put("min_target_error", _real("min_target_error", self.min_target_error, 0.0, 1.0,
                                      lo_open=True))

    @classmethod
    def of(cls, max_photons: int | None = None,
           min_target_error: float | None = None) -> "ServiceLimits":
        """The limits given on the command line (None: the default)."""
        return cls(max_photons if max_photons is not None else SERVICE_MAX_PHOTONS,
                   min_target_error if min_target_error is not None
                   else SERVICE_MIN_TARGET_ERROR)

    def check(self, settings: TraceSettings, options: bool = False) -> None:
        """Raise :class:`SettingsError` naming ``photons`` or ``target_error`` (or, with
        ``options``, the command line's option) where ``settings`` asks for more work."""
        if settings.photons is not None and settings.photons > self.max_photons:
            raise SettingsError(f"must be at most {self.max_photons:,} (the service's "
                                f"--max-photons), got {settings.photons:,}",
                                prop="--photons" if options else "photons")
        if settings.target_error is not None and \
                settings.target_error < self.min_target_error:
            raise SettingsError(f"must be at least {self.min_target_error:g} (the "
                                f"service's --min-target-error), got "
                                f"{settings.target_error:g}",
                                prop="--target-error" if options else "target_error")


def with_knobs(settings: TraceSettings, changes: dict) -> tuple[TraceSettings, bool | None]:
    """``settings`` with a client's ``changes`` of :data:`KNOBS` (checked as the command
    line's are: one :class:`SettingsError` names a bad one), and ``paused`` (None: not
    said). A photon budget given ends the target error, and a target the budget."""
    unknown = sorted(set(changes) - set(KNOBS))
    if unknown:
        raise SettingsError(f"unknown setting(s) {', '.join(unknown)}; known: "
                            f"{', '.join(sorted(KNOBS))}")
    paused = changes.get("paused", None)
    if paused is not None and not isinstance(paused, bool):
        raise SettingsError(f"must be true or false, got {paused!r}", prop="paused")
    knobs = {k: v for k, v in changes.items() if k != "paused"}
    if "photons" in knobs and knobs["photons"] is not None:
        knobs.setdefault("target_error", None)
    elif "target_error" in knobs and knobs["target_error"] is not None:
        knobs.setdefault("photons", None)
    return (replace(settings, **knobs) if knobs else settings), paused  # replace checks
