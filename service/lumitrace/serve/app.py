"""The HTTP face of the service (aiohttp): status, deltas, the event stream, results.

Every answer is JSON (the event stream excepted); every failure is a 4xx or 5xx JSON body
``{"error": ..., "problems": [{"where", "why"}, ...]}`` and never stops the service. Every
request passes the :class:`~lumitrace.serve.guard.Guard` (Host, Origin, JSON bodies, the
page's key) and, with a token, the bearer check, before its handler runs.
"""
from __future__ import annotations

import asyncio
import json
from typing import Any

from aiohttp import web

from ..delta.protocol import DeltaError, delta_schema, parse_json_object, parse_request
from ..errors import LumitraceError
from ..run.settings import ServiceLimits, with_knobs
from .engine import Engine
from .events import EventLog
from .fitting import FitRequest, LiveFit, revision_target
from .guard import Guard
from .live import LiveStage
from .reference import MAX_FILE_CHARS, KeptFrames, reference_frame
from .viewer import PAGE_DIR, PAGE_FILES, PreviewCache, editable_scene, geometry_frame

#: Largest request body accepted (bytes): a layer fragment or a mesh's points fit.
MAX_BODY_BYTES = 8 << 20
#: What the page may load: its own files only (no CDN, no network), inline styles; no
#: other page may frame it.
PAGE_POLICY = ("default-src 'self'; img-src 'self' data:; style-src 'self' 'unsafe-inline'; "
               "frame-ancestors 'none'")
#: Where the page file holds the service's key (:attr:`Guard.key`), replaced when served.
KEY_PLACEHOLDER = b"LUMITRACE-KEY"
#: Seconds between keep-alive comments on an idle event stream.
KEEPALIVE_SECONDS = 15.0


def _json(data: Any, status: int = 200) -> web.Response:
    return web.json_response(data, status=status,
                             dumps=lambda d: json.dumps(d, allow_nan=False, default=str))


def _problem(status: int, message: str, problems=()) -> web.Response:
    return _json({"error": message, "problems": [p.as_dict() for p in problems]}, status)


def make_app(live: LiveStage, engine: Engine, events: EventLog,
             token: str | None = None, viewer: bool = True,
             guard: Guard | None = None,
             limits: ServiceLimits | None = None) -> web.Application:
    """The aiohttp application of a running service (with the live view page unless
    ``viewer`` is False); ``guard`` holds its Host names, token and page key (a service
    bound to 127.0.0.1 when None); ``limits`` bound the work /settings may ask for."""
    limits = limits if limits is not None else ServiceLimits()
    if guard is None:
        guard = Guard(token=token)
    elif guard.token != token:
        raise ValueError("the guard's token is not the service's")
    kept = KeptFrames()
    previews = PreviewCache(kept)
    if viewer:  # an edit's first preview is made as soon as its map is, before its files
        # (its UGR figures with the next frame; a done revision's, kept, has them)
        engine.refreshed = lambda: previews.get(engine, hold=False, ugr=engine.done)

    @web.middleware
    async def checks(request: web.Request, handler):
        # the page's own files hold no data: they load from a link anywhere and without
        # the token, and the page then sends its key and the token with every request
        public = viewer and request.method in ("GET", "HEAD") and (
            request.path == "/" or request.path.startswith("/page/"))
        refusal = guard.check(request.method, request.headers,
                              request.content_type if "Content-Type" in request.headers
                              else "", page_file=public)
        if refusal is not None:
            return _problem(refusal.status, refusal.message)
        try:
            return await handler(request)
        except web.HTTPException as exc:
            if exc.status >= 400:
                return _problem(exc.status, exc.reason)
            raise
        except (asyncio.CancelledError, ConnectionResetError):
            raise
        except Exception as exc:  # the service keeps serving whatever a request does
            events.publish("error", message=f"{request.method} {request.path}: {exc!r}")
            return _problem(500, f"internal error: {type(exc).__name__}: {exc}")

    async def status(_request: web.Request) -> web.Response:
        return _json({"revision": live.revision, "stage": str(live.stage_path),
                      "edits_layer": str(live.edits_path), **engine.status()})

    async def deltas(request: web.Request) -> web.Response:
        try:
            raw = await request.read()
        except web.HTTPRequestEntityTooLarge:
            return _problem(413, f"request body larger than {MAX_BODY_BYTES} bytes")
        try:  # decoding and checking a mesh's points take a second: not on the event loop
            body = await asyncio.get_running_loop().run_in_executor(None, parse_request, raw)
            revision = await live.acall(live.apply, body["deltas"], body.get("base_revision"))
        except DeltaError as exc:
            return _problem(exc.status, str(exc), exc.problems)
        except LumitraceError as exc:
            return _problem(422, str(exc))
        engine.submit(revision)
        return _json({"revision": revision.number, "effect": revision.effect.as_dict(),
                      "edits_layer": str(live.edits_path)})

    async def results(_request: web.Request) -> web.Response:
        record, written = engine.record, engine.written
        if record is None:
            return _problem(404, "no result written yet")
        return _json({"revision": written.get("revision"),
                      "input_hash": written.get("input_hash"),
                      "pictures": written.get("pictures"), **record.summary()})

    async def schema(_request: web.Request) -> web.Response:
        return _json(delta_schema())

    async def stream(request: web.Request) -> web.StreamResponse:
        last = request.headers.get("Last-Event-ID") or request.query.get("last_id") or "0"
        try:
            last_id = max(0, int(last))
        except ValueError:
            return _problem(400, f"Last-Event-ID must be an event id, got {last!r}")
        if not request.headers.get("Last-Event-ID"):  # a resuming client goes on from its id
            try:
                last_id, gap = _start(events, request.query, last_id)
            except ValueError as exc:
                return _problem(400, str(exc))
        else:
            last_id, gap = events.resume(last_id)
        if request.query.get("format") == "json":  # the history so far, not a stream
            return _json({"events": [e.as_dict() for e in events.since(last_id)],
                          "oldest_id": events.oldest_id(), "first_id": events.first_id,
                          "gap": gap})
        response = web.StreamResponse(headers={"Content-Type": "text/event-stream",
                                               "Cache-Control": "no-cache"})
        await response.prepare(request)
        if gap is not None:
            await response.write(f"event: gap\ndata: {json.dumps(gap)}\n\n".encode())
        try:
            while not events.closed:
                batch = await events.wait(last_id, KEEPALIVE_SECONDS)
                if not batch:
                    await response.write(b": keep-alive\n\n")
                    continue
                await response.write(b"".join(e.sse() for e in batch))
                last_id = batch[-1].id
        except (ConnectionResetError, asyncio.CancelledError):
            pass
        return response

    async def page(request: web.Request) -> web.Response:
        name = request.match_info.get("name", "index.html")
        if name not in PAGE_FILES:
            return _problem(404, f"no page file {name!r}")
        body = (PAGE_DIR / name).read_bytes()
        if name == "index.html":  # the key, for this origin's eyes only (never cached)
            body = body.replace(KEY_PLACEHOLDER, guard.key.encode())
        return web.Response(body=body, content_type=PAGE_FILES[name],
                            headers={"Cache-Control": "no-store" if name == "index.html"
                                     else "no-cache",
                                     "Content-Security-Policy": PAGE_POLICY,
                                     "X-Frame-Options": "DENY",
                                     "Referrer-Policy": "no-referrer"})

    async def preview(_request: web.Request) -> web.Response:
        data = await asyncio.get_running_loop().run_in_executor(None, previews.get, engine)
        if data is None:  # not an error: a client waits for the first frame quietly
            return web.Response(status=204, headers={"Cache-Control": "no-store"})
        return web.Response(body=data, content_type="application/octet-stream",
                            headers={"Cache-Control": "no-store"})

    async def geometry(_request: web.Request) -> web.Response:
        rev = engine.revision
        if rev is None:
            return _problem(404, "no revision taken yet")
        data = await asyncio.get_running_loop().run_in_executor(
            None, geometry_frame, rev.scene, rev.number)
        return web.Response(body=data, content_type="application/octet-stream")

    async def scene(_request: web.Request) -> web.Response:
        rev = engine.revision
        if rev is None:
            return _problem(404, "no revision taken yet")
        return _json(editable_scene(rev.scene, rev.number, rev.transforms))

    async def settings(request: web.Request) -> web.Response:
        if request.method == "GET":
            return _json(engine.session_settings())
        try:
            body = parse_json_object(await request.read())
            limits.check(with_knobs(engine.settings, body)[0])  # the command line's ranges
            return _json(engine.update_settings(body))
        except DeltaError as exc:
            return _problem(exc.status, str(exc), exc.problems)
        except LumitraceError as exc:
            return _problem(422, str(exc))

    app = web.Application(middlewares=[checks], client_max_size=MAX_BODY_BYTES)
    app.add_routes([web.get("/status", status), web.post("/deltas", deltas),
                    web.get("/events", stream), web.get("/results", results),
                    web.get("/schema", schema), web.get("/preview", preview),
                    web.get("/geometry", geometry), web.get("/scene", scene),
                    web.get("/settings", settings), web.post("/settings", settings)])
    if viewer:
        app.add_routes([web.get("/", page), web.get("/page/{name}", page)])
        app.add_routes(_compare_routes(kept))
    app["fit"] = fit = LiveFit(live.stage_path, live.edits_path, live.luminaire,
                               fit_folder(live, engine), events.publish)
    app.add_routes(_fit_routes(live, engine, fit, limits, kept))
    return app


def fit_folder(live: LiveStage, engine: Engine):
    """Where the live view's fits write: ``fit/`` in the service's output folder, else
    ``NAME.fit`` beside the stage (as ``lumitrace fit`` does)."""
    from ..filenames import stage_name

    if engine.out_dir is not None:
        return engine.out_dir / "fit"
    return live.stage_path.with_name(f"{stage_name(live.stage_path)}.fit")


def _fit_routes(live: LiveStage, engine: Engine, fit: LiveFit,
                limits: ServiceLimits, kept: KeptFrames) -> list:
    """A fit started from the page (:mod:`~lumitrace.serve.fitting`): its state, start,
    stop, and its best applied as a delta; its photons and final error within the
    service's ``limits``, as ``/settings``'s are."""

    async def state(_request: web.Request) -> web.Response:
        return _json(fit.status())

    async def start(request: web.Request) -> web.Response:
        from ..fit.parameters import resolve

        loop = asyncio.get_running_loop()
        try:
            raw = parse_json_object(await request.read())
            if isinstance(raw.get("target"), dict) and "revision" in raw["target"]:
                raw["target"] = revision_target(kept, raw["target"]["revision"])
            body = FitRequest.of(raw)
            if body.photons > limits.max_photons:
                return _problem(422, f"/photons: at most {limits.max_photons:,} (the "
                                     "service's --max-photons)")
            if body.final_error < limits.min_target_error:
                return _problem(422, f"/final_error: at least {limits.min_target_error:g} "
                                     "(the service's --min-target-error)")
            # the parameters and the target read before anything starts
            await live.acall(lambda: resolve(live.stage, list(body.vary)))
            await loop.run_in_executor(None, reference_frame, body.target_name,
                                       body.target_text)
            return _json(fit.start(body), 202)
        except DeltaError as exc:
            return _problem(exc.status, str(exc), exc.problems)
        except LumitraceError as exc:
            return _problem(422, str(exc))

    async def stop(_request: web.Request) -> web.Response:
        try:
            return _json(fit.stop())
        except DeltaError as exc:
            return _problem(exc.status, str(exc), exc.problems)

    async def apply(_request: web.Request) -> web.Response:
        try:
            number, layer, undo = fit.layer_to_apply()
            revision = await live.acall(live.apply, [{"op": "layer", "usda": layer}])
        except DeltaError as exc:
            return _problem(exc.status, str(exc), exc.problems)
        except LumitraceError as exc:
            return _problem(422, str(exc))
        engine.submit(revision)
        fit.applied(number, revision.number)
        return _json({"revision": revision.number, "effect": revision.effect.as_dict(),
                      "fit": number, "edits_layer": str(live.edits_path),
                      "inverse": [{"op": "layer", "usda": undo}]})

    return [web.get("/fit", state), web.post("/fit", start), web.post("/fit/stop", stop),
            web.post("/fit/apply", apply)]


def _start(events: EventLog, query, last_id: int) -> tuple[int, dict | None]:
    """Where a new stream (or history) starts: after ``last_id`` (``last_id=``), after the
    newest event (``since=now``: from now on), or at the first event of revision ``N`` or
    later (``revision=N``); and the gap to report. Raises ValueError for a bad query."""
    since, revision = query.get("since"), query.get("revision")
    if since is not None and since != "now":
        raise ValueError(f"since must be 'now', got {since!r}")
    if since is not None and revision is not None:
        raise ValueError("give since=now or revision=N, not both")
    if since == "now":
        return events.newest_id(), None
    if revision is not None:
        try:
            number = int(revision)
        except ValueError:
            raise ValueError(f"revision must be a revision number, got {revision!r}") \
                from None
        return events.before_revision(number)
    return events.resume(last_id)


def _compare_routes(kept: KeptFrames) -> list:
    """What the live view compares with: the kept preview frames of recent revisions, and
    a target photometric file made into a frame."""

    async def revisions(_request: web.Request) -> web.Response:
        return _json({"revisions": kept.summaries()})

    async def revision_preview(request: web.Request) -> web.Response:
        try:
            number = int(request.match_info["number"])
        except ValueError:
            return _problem(400, f"not a revision number: {request.match_info['number']!r}")
        data = kept.get(number)
        if data is None:
            return _problem(404, f"no preview of revision {number} is kept (the newest "
                                 "revisions' are: GET /revisions)")
        return web.Response(body=data, content_type="application/octet-stream",
                            headers={"Cache-Control": "no-store"})

    async def reference(request: web.Request) -> web.Response:
        try:
            body = parse_json_object(await request.read())
        except DeltaError as exc:
            return _problem(exc.status, str(exc), exc.problems)
        name, text = body.get("name", "target"), body.get("text")
        if not isinstance(name, str) or not isinstance(text, str):
            return _problem(400, "give the file as {\"name\": NAME, \"text\": ITS TEXT} "
                                 "(strings)")
        if len(text) > MAX_FILE_CHARS:
            return _problem(413, f"the file is larger than {MAX_FILE_CHARS} characters")
        try:
            data = await asyncio.get_running_loop().run_in_executor(
                None, reference_frame, name, text)
        except LumitraceError as exc:
            return _problem(422, str(exc))
        return web.Response(body=data, content_type="application/octet-stream",
                            headers={"Cache-Control": "no-store"})

    return [web.get("/revisions", revisions),
            web.get("/revisions/{number}/preview", revision_preview),
            web.post("/reference", reference)]
