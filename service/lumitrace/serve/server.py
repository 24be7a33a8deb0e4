"""``lumitrace serve``: the live stage, the engine, the watcher and the HTTP app in one
process, started and stopped cleanly (SIGINT, SIGTERM and SIGHUP write a final result)."""
from __future__ import annotations

import asyncio
import ipaddress
import signal
import socket
import warnings
from pathlib import Path

from aiohttp import web

from ..errors import LumitraceError, LumitraceWarning
from ..run.settings import ServiceLimits, TraceSettings
from .app import make_app
from .engine import Engine
from .events import EventLog
from .guard import Guard
from .live import LiveStage
from .lock import StageLock
from .log import echo_events
from .state import EVENT_BLOCK, ServiceState
from .watcher import watch_layers

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8650


def is_loopback(host: str) -> bool:
    """Whether every address ``host`` names is a loopback address."""
    try:
        infos = socket.getaddrinfo(host, None)
    except socket.gaierror:
        return False
    return bool(infos) and all(ipaddress.ip_address(i[4][0].split("%")[0]).is_loopback
                               for i in infos)


def check_binding(host: str, token: str | None) -> None:
    """A host other than loopback needs a token: the service would otherwise accept
    edits from anyone who can reach it."""
    if not is_loopback(host) and not token:
        raise LumitraceError(f"--host {host} is reachable from other machines: give --token "
                             "(clients then send 'Authorization: Bearer TOKEN')")


def serve(stage: Path, settings: TraceSettings, host: str = DEFAULT_HOST,
          port: int = DEFAULT_PORT, token: str | None = None,
          out_dir: Path | None = None, viewer: bool = True, quiet: bool = False,
          sublayer: bool = True, deliverables: bool = False, allow_hosts=(),
          limits: tuple[int | None, float | None] = (None, None)) -> int:
    """Run the service until a signal; return the exit status (0). ``viewer`` serves the
    live view page at ``/``; ``quiet`` says nothing on stderr but the fatal; ``sublayer``
    False leaves the stage file untouched (the result layer is not sublayered into it);
    ``deliverables`` writes the datasheet and the GLDF container with the pictures;
    ``allow_hosts`` are the names besides loopback ones and ``host`` that requests may
    give as their ``Host``; ``limits`` (the largest photon budget, the smallest target
    error; None: the default) bound what a client may set through /settings."""
    check_binding(host, token)
    try:
        guard = Guard.of(host, allow_hosts, token)
    except ValueError as exc:
        raise LumitraceError(str(exc)) from None
    limits = ServiceLimits.of(*limits)
    limits.check(settings, options=True)
    lock = StageLock.acquire(stage)  # before the edits layer is read: one service a stage
    try:
        state = ServiceState.of(stage)  # revisions and event ids go on from the last run
        events = EventLog(first_id=state.first_event_id(), reserve=state.reserve_events,
                          block=EVENT_BLOCK)
        live = LiveStage(stage, state=state)
        engine = Engine(live, settings, events, out_dir, sublayer=sublayer,
                        deliverables=deliverables)
        try:
            asyncio.run(_main(live, engine, events, host, port, token, lock, viewer, quiet,
                              guard, limits))
        finally:
            live.close()
    finally:
        lock.release()
    return 0


def _route_warnings(events: EventLog) -> None:
    """lumitrace warnings become events (lines on stderr with the others), each time they
    happen."""
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, LumitraceWarning):
            events.publish("warning", message=str(message))
        else:
            shown(message, category, filename, lineno, file, line)
    warnings.showwarning = show
    warnings.simplefilter("always", LumitraceWarning)


async def _main(live: LiveStage, engine: Engine, events: EventLog, host: str, port: int,
                token: str | None, lock: StageLock, viewer: bool = True,
                quiet: bool = False, guard: Guard | None = None,
                limits: ServiceLimits | None = None) -> None:
    loop = asyncio.get_running_loop()
    events.bind(loop)
    echo = None if quiet else asyncio.create_task(echo_events(events))
    _route_warnings(events)
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        loop.add_signal_handler(sig, stop.set)
    runner = web.AppRunner(make_app(live, engine, events, token, viewer, guard, limits),
                           handle_signals=False,
                           access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port, reuse_address=True)
    await site.start()
    bound = runner.addresses[0]
    url = f"http://{bound[0] if ':' not in bound[0] else '[' + bound[0] + ']'}:{bound[1]}/"
    lock.record(port=bound[1], url=url)
    print(f"lumitrace: serving {live.stage_path} at {url} (revision {live.revision}, edits "
          f"in {live.edits_path.name})", flush=True)
    if viewer:
        print(f"lumitrace: live view at {url} (open it in a browser)", flush=True)
    events.publish("started", url=url, revision=live.revision, stage=str(live.stage_path))
    engine.start(live.start())
    watcher = asyncio.create_task(watch_layers(live, engine.submit, events, stop,
                                               engine.report_error))
    await stop.wait()
    events.publish("stopping", revision=live.revision)
    await loop.run_in_executor(None, runner.app["fit"].close)
    await loop.run_in_executor(None, engine.stop)
    events.close()
    if echo is not None:
        await echo  # the last events' lines
    watcher.cancel()
    try:
        await watcher
    except (asyncio.CancelledError, Exception):
        pass
    await runner.cleanup()
    print(f"lumitrace: stopped; last result written for revision "
          f"{engine.written.get('revision')} ({engine.written.get('photons') or 0:,} photons)",
          flush=True)
