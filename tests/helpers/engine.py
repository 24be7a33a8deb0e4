"""The demo's tracing engine in process, and the deltas its tests send."""
from __future__ import annotations

import contextlib
import shutil

from lumitrace.run.settings import TraceSettings
from lumitrace.serve.engine import Engine
from lumitrace.serve.events import EventLog
from lumitrace.serve.live import LiveStage

from .paths import ROOT

REFLECTOR = "/Luminaire/Materials/ReflectorAluminium"
SETTINGS = TraceSettings(photons=40_000, resolution=16, threads=2, seed=5)


def set_delta(path: str, prop: str, value) -> list[dict]:
    """The deltas that set one property."""
    return [{"op": "set", "path": path, "property": prop, "value": value}]


@contextlib.contextmanager
def running_engine(folder, refreshed=None):
    """The demo's engine, started in ``folder`` (``refreshed`` its live view's hook from the
    start); yields (live stage, engine)."""
    shutil.copy(ROOT / "stages" / "downlight.usda", folder / "downlight.usda")
    live = LiveStage(folder / "downlight.usda")
    eng = Engine(live, SETTINGS, EventLog(first_id=1), folder / "out")
    eng.refreshed = refreshed
    eng.start(live.start())
    try:
        yield live, eng
    finally:
        eng.stop()
        live.close()
