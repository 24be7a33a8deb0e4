"""The live link from Blender to a running ``lumitrace serve``.

Every tick (a Blender timer, 10 times a second) the link compares what Blender shows of
the imported stage with what it last sent; once the state has held still for
``debounce`` seconds (a drag has ended) the difference goes to the service as one batch
of scene deltas. A thread reads the service's events (its kept history, after the last
one seen); the tick takes them on Blender's main thread, and when a newer result is
written it loads the service's IES file into the photometric light (:mod:`.ies_light`)
at the luminaire's place.

Nothing here waits on the service inside a tick longer than one HTTP request.
"""
from __future__ import annotations

import atexit
import math
import os
import queue
import threading
import time

import bpy
import mathutils

from . import exporter, ies_light, records, state
from .http import Service, ServiceError
from .usd import pxr_modules

#: Seconds the state must hold still before it is sent (a drag sends once, at its end).
DEBOUNCE = 0.3
TICK = 0.1
#: Seconds between two reads of the service's events.
FOLLOW = 0.1
#: The links of this Blender session, by scene name.
LINKS: dict[str, "LiveLink"] = {}


def deltas_of(entry: dict, changes: list[state.Edit]) -> list[dict]:
    """The scene deltas of ``changes``: a move is one ``transform``, a value one ``set``;
    new prims and what the protocol has no op for go as one ``layer`` fragment."""
    Usd, Sdf, UsdGeom, UsdLux, UsdShade, Gf, Vt = pxr_modules()
    out, fragment = [], []
    new_roots = {e.path for e in changes if e.op == "define"}
    for e in changes:
        if any(e.path == r or e.path.startswith(r + "/") or e.path.startswith(r + ".")
               for r in new_roots) or e.op in ("block", "connect"):
            fragment.append(e)
        elif e.op == "transform":
            m = e.matrix
            out.append({"op": "transform", "path": e.path,
                        "matrix": [list(m[4 * r:4 * r + 4]) for r in range(4)]})
        elif e.op == "set":
            delta = {"op": "set", "path": e.path, "property": e.prop,
                     "value": _json_value(e.value, e.usd_type)}
            if not e.prop.startswith("lumitrace:"):
                delta["type"] = e.usd_type
            out.append(delta)
        elif e.op == "bind":
            out.append({"op": "bind", "path": e.path, "material": e.material})
        elif e.op == "active":
            out.append({"op": "active", "path": e.path, "active": bool(e.value)})
        elif e.op == "visibility":
            out.append({"op": "set", "path": e.path, "property": "visibility",
                        "value": "inherited" if e.value else "invisible", "type": "token"})
        else:
            fragment.append(e)
    if fragment:
        layer = exporter.edits_layer(entry, fragment)
        out.insert(0, {"op": "layer", "usda": layer.ExportToString()})
    return out


def _json_value(value, usd_type: str):
    if usd_type == "point3f[]":
        flat = list(value)
        return [flat[i:i + 3] for i in range(0, len(flat), 3)]
    if hasattr(value, "tolist"):
        return value.tolist()
    return list(value) if isinstance(value, tuple) else value


class LiveLink:
    """A link between the stage ``entry`` imported into ``scene`` and the service at
    ``url``. ``clock`` gives seconds (tests drive it); ``follow`` starts the thread that
    reads the event stream."""

    def __init__(self, scene, url: str, token: str | None = None, stage: str | None = None,
                 debounce: float = DEBOUNCE, clock=time.monotonic, follow: bool = True):
        self.scene_name = scene.name
        self.entry = records.stage_entry(scene, stage)
        self.service = Service(url, token)
        self.debounce = float(debounce)
        self.clock = clock
        status = self.service.status()
        served = status.get("stage", "")
        if served and os.path.realpath(served) != self.entry["file"]:
            raise ServiceError(0, f"the service at {url} serves {served}, not the imported "
                                  f"stage {self.entry['file']}")
        self.status = status
        self.results: dict = {}
        self.revision = int(status.get("revision", 0))
        self.sent_revisions: list[int] = []
        self.batches: list[list[dict]] = []
        self.error = ""
        self.light_revision = -1
        self.light_ies = ""
        # what the service has of Blender's view: the stage as imported
        self.sent = state.recorded_state(self.entry)
        self.seen = self.sent
        self.changed_at = self.clock()
        self.next_poll = -math.inf
        self.events: queue.Queue = queue.Queue()
        kept = self.service.history(0)  # what happened before the link is not its news
        self.last_event_id = max((int(e["id"]) for e in kept), default=0)
        self._stop = threading.Event()
        self._thread = None
        self.timer = None  # the Blender timer ticking the link (see connect)
        if follow:
            self._thread = threading.Thread(target=self._follow, daemon=True,
                                            name="lumitrace events")
            self._thread.start()

    @property
    def scene(self):
        return bpy.data.scenes.get(self.scene_name)

    # -- sending ---------------------------------------------------------------------------

    def poll(self, now: float | None = None) -> dict | None:
        """Send what changed once it has held still for ``debounce`` s; returns the
        service's answer to the batch sent (None: nothing sent)."""
        now = self.clock() if now is None else now
        current = state.state_of_stage(self.entry, cached=True)
        if not _same_state(current, self.seen):
            self.seen, self.changed_at = current, now
            return None
        if _same_state(current, self.sent) or now - self.changed_at < self.debounce:
            return None
        try:
            deltas = deltas_of(self.entry, state.edits(self.entry, self.sent, current))
        except state.ExportError as exc:
            self.error = str(exc)
            self.sent = current  # not sent again until it changes
            return None
        if not deltas:
            self.sent = current
            return None
        try:
            answer = self.service.send(deltas)
        except ServiceError as exc:
            self.error = str(exc)
            if exc.status:  # refused: not sent again until it changes
                self.sent = current
            return None  # unreachable: sent again at the next tick
        self.sent = current
        self.error = ""
        self.batches.append(deltas)
        self.revision = int(answer.get("revision", self.revision))
        self.sent_revisions.append(self.revision)
        return answer

    # -- receiving -------------------------------------------------------------------------

    def _follow(self) -> None:
        """The service's events, into ``self.events``: its kept history after the last id
        seen, read every :data:`FOLLOW` s (short requests, so closing never waits on a
        stream)."""
        while not self._stop.is_set():
            try:
                for e in self.service.history(self.last_event_id):
                    self.last_event_id = max(self.last_event_id, int(e["id"]))
                    self.events.put((e["id"], e["event"], e["data"]))
            except (ServiceError, KeyError, ValueError) as exc:
                self.error = str(exc)
            self._stop.wait(FOLLOW)

    def take_events(self, events=None) -> bool:
        """Handle the events received (or ``events``: ``(id, kind, data)``); True when a
        newer result was loaded into the light."""
        loaded = False
        pending = list(events or [])
        while True:
            try:
                pending.append(self.events.get_nowait())
            except queue.Empty:
                break
        newest_written = None
        for _, kind, data in pending:
            if kind == "revision":
                self.revision = max(self.revision, int(data.get("revision", 0)))
            elif kind == "iteration":
                self.status.update({k: data[k] for k in ("photons", "relative_error")
                                    if k in data})
            elif kind == "written":
                newest_written = data
            elif kind == "error":
                self.error = str(data.get("message", data))
        if newest_written is not None:
            loaded = self.refresh()
        return loaded

    def wait_for(self, predicate, timeout: float = 120.0):
        """Take events until one satisfies ``predicate(kind, data)`` (handling each as the
        tick does); returns its data. Raises TimeoutError after ``timeout`` s without it."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("the service sent no such event")
            try:
                event = self.events.get(timeout=left)
            except queue.Empty:
                continue
            self.take_events([event])
            if predicate(event[1], event[2]):
                return event[2]

    def refresh(self) -> bool:
        """Read the service's status and newest result; load its IES into the light when
        it is newer than the one shown. True when the light changed."""
        try:
            self.status = self.service.status()
            results = self.service.results()
        except ServiceError as exc:
            if exc.status != 404:  # 404: nothing written yet
                self.error = str(exc)
            return False
        self.results = results
        revision = int(results.get("revision", -1))
        ies_path = (results.get("outputs") or {}).get("ies")
        if not ies_path or not os.path.isfile(ies_path):
            return False
        with open(ies_path, encoding="utf-8", errors="replace") as f:
            text = f.read()
        if revision == self.light_revision and text == self.light_ies:
            return False
        scene = self.scene
        matrix = self.light_matrix(results.get("outputs", {}).get("result_layer"))
        ies_light.show_ies(scene, text, matrix)
        photometric_view(self.entry, True)
        self.light_revision, self.light_ies = revision, text
        return True

    def light_matrix(self, result_layer: str | None):
        """World matrix of the photometric light: the luminaire's object, times the place
        lumitrace gives its stand-in light in the result layer (its luminous opening's
        centre; the luminaire's origin where the layer has none)."""
        root = luminaire_object(self.entry)
        world = root.matrix_world.copy() if root is not None else mathutils.Matrix()
        local = mathutils.Matrix()
        if result_layer and os.path.isfile(result_layer):
            local = photometric_light_local(result_layer, self.entry["luminaire"])
        return world @ local

    def tick(self, now: float | None = None) -> None:
        """One step of the link, as the timer runs it. Reading Blender's state costs time
        on Blender's own thread (a mesh of a million triangles is hashed in tens of ms):
        the next read waits ten times what the last one took, so it never takes more than
        a tenth of that thread."""
        now = self.clock() if now is None else now
        if now >= self.next_poll:
            started = time.perf_counter()
            self.poll(now)
            self.next_poll = now + 10.0 * (time.perf_counter() - started)
        self.take_events()

    def close(self, restore: bool = True) -> None:
        """Stop reading events; with ``restore``, the imported lights and parts render
        as before the link."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if restore:
            photometric_view(self.entry, False)


def _same_state(a: dict, b: dict) -> bool:
    if a.keys() != b.keys():
        return False
    return all(state._same(a[k], b[k]) for k in a)


def photometric_view(entry: dict, on: bool) -> None:
    """Let the photometric light stand for the luminaire in renders (``on``): the
    imported emitters give no light (their flux is in the IES light) and the parts cast
    no shadow (the IES light sits inside them). Off restores both. Neither is exported."""
    from .importer import LUMENS_PER_WATT
    scene = bpy.context.scene
    scale = ies_light.light_energy(scene)
    for obj, rec in state.imported_objects(entry["file"]):
        if rec["kind"] == "light" and obj.data is not None:
            flux = obj.data.get("lumitrace:luminousFlux")
            obj.data.energy = 0.0 if on else (float(flux) / LUMENS_PER_WATT * scale
                                              if flux else obj.data.energy)
        elif obj.type == "MESH":
            obj.visible_shadow = not on


def luminaire_object(entry: dict):
    """The Blender object of the stage's luminaire prim (None if it is gone)."""
    for obj, rec in state.imported_objects(entry["file"]):
        if rec["prim"] == entry["luminaire"]:
            return obj
    return None


def photometric_light_local(result_layer: str, luminaire: str):
    """The local matrix (Blender's convention) of lumitrace's stand-in light, read fresh
    from the result layer's ``photometric`` representation."""
    Usd, Sdf, UsdGeom, UsdLux, UsdShade, Gf, Vt = pxr_modules()
    layer = Sdf.Layer.OpenAsAnonymous(result_layer)
    if layer is None:
        return mathutils.Matrix()
    stage = Usd.Stage.Open(layer)
    prim = stage.GetPrimAtPath(luminaire)
    if not prim:
        return mathutils.Matrix()
    variants = prim.GetVariantSets()
    if "lumitraceRepresentation" not in variants.GetNames():
        return mathutils.Matrix()
    variants.GetVariantSet("lumitraceRepresentation").SetVariantSelection("photometric")
    light = stage.GetPrimAtPath(luminaire + "/lumitracePhotometricLight")
    if not light:
        return mathutils.Matrix()
    m = UsdGeom.Xformable(light).GetLocalTransformation()
    return mathutils.Matrix([[m[c][r] for c in range(4)] for r in range(4)])


def connect(scene, url: str, token: str | None = None, stage: str | None = None,
            timer: bool = True, **kwargs) -> LiveLink:
    """Link ``scene`` to the service at ``url`` (replacing a link it had); with
    ``timer``, a Blender timer ticks it."""
    disconnect(scene)
    link = LiveLink(scene, url, token, stage, **kwargs)
    LINKS[scene.name] = link
    link.refresh()  # the result the service has already written
    if timer:
        def tick():
            if LINKS.get(link.scene_name) is not link:
                return None
            try:
                link.tick()
            except Exception as exc:  # noqa: BLE001 - shown in the panel, link kept
                link.error = f"{type(exc).__name__}: {exc}"
            return TICK
        link.timer = tick
        bpy.app.timers.register(tick, first_interval=TICK, persistent=True)
    return link


@atexit.register
def _disconnect_all() -> None:
    """Every link's timer and thread stopped while Python still runs (Blender frees what
    is left after it); Blender's data is not touched, it may be gone."""
    for name in list(LINKS):
        link = LINKS.pop(name)
        _stop_timer(link)
        link.close(restore=False)


def _stop_timer(link: LiveLink) -> None:
    # a Python timer left registered when Blender exits is freed after Python is, and
    # Blender as a module then never exits
    try:
        if link.timer is not None and bpy.app.timers.is_registered(link.timer):
            bpy.app.timers.unregister(link.timer)
    except (AttributeError, ValueError):
        pass


def disconnect(scene) -> bool:
    link = LINKS.pop(scene.name, None)
    if link is None:
        return False
    _stop_timer(link)
    link.close()
    return True
