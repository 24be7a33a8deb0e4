"""An unreadable layer is retried for RETRY_SECONDS of wall time, however long each read
takes: a stage that is slow to read (a large layer, a loaded machine) is reported after the
same window, not after thirty of its reads."""
from __future__ import annotations

import asyncio
import time
from pathlib import Path

from lumitrace.serve import watcher
from lumitrace.serve.live import LayerUnreadable


class _SlowBrokenStage:
    """A live stage whose every read takes 0.3 s and finds the layer unreadable."""

    revision = 4

    def __init__(self):
        self.reads = 0
        self.troubled = []

    async def acall(self, fn, *args):
        return fn(*args)

    def reload(self, paths):
        self.reads += 1
        time.sleep(0.3)
        raise LayerUnreadable("cannot read layer.usda", Path("layer.usda"))

    def trouble(self, path):
        self.troubled.append(path)


class _Events:
    def __init__(self):
        self.published = []

    def publish(self, kind, message, **data):
        self.published.append((kind, message, time.monotonic()))


def test_an_unreadable_layer_is_reported_after_the_window_in_wall_time(monkeypatch):
    monkeypatch.setattr(watcher, "RETRY_SECONDS", 1.0)
    live, events = _SlowBrokenStage(), _Events()
    start = time.monotonic()
    asyncio.run(watcher._reload(live, {Path("layer.usda")}, lambda r: None,
                                watcher._Errors(events, None)))
    (kind, message, at), = events.published
    assert kind == "error" and "keeping revision 4" in message
    assert 1.0 <= at - start < 1.0 + 0.3 + watcher.RETRY_STEP + 0.5  # not 10 reads of 0.4 s
    assert live.reads <= 4 and live.troubled == [Path("layer.usda")]


def test_a_save_landing_while_a_revision_is_read_is_not_taken_for_it(tmp_path, monkeypatch):
    """A program saves the stage again while the service reads the revision of its last
    save: the new save is still news to the watcher (a revision, or here, broken, an
    error), not taken for the content loaded and lost."""
    import shutil

    import lumitrace  # noqa: F401  (the schema registered before any stage is composed)
    from lumitrace.serve import live as live_module
    from lumitrace.serve.live import LiveStage

    stage = tmp_path / "downlight.usda"
    shutil.copy(Path(__file__).resolve().parents[2] / "stages" / "downlight.usda", stage)
    good = stage.read_text()
    live = LiveStage(stage)
    stage.write_text(good.replace("lumitrace:roughness = 0.15", "lumitrace:roughness = 0.3"))
    read = live_module.scene_from_stage

    def read_while_saved(*args, **kwargs):  # the next save lands as the scene is read
        stage.write_text("#usda 1.0\n(\n")
        return read(*args, **kwargs)

    monkeypatch.setattr(live_module, "scene_from_stage", read_while_saved)
    revision = live.reload({stage})
    monkeypatch.setattr(live_module, "scene_from_stage", read)
    assert revision is not None and revision.number == live.revision
    try:
        again = live.reload({stage})
    except LayerUnreadable as exc:  # the broken save, seen
        assert "Expected )" in str(exc) and exc.path == stage.absolute()
    else:
        raise AssertionError(f"the save made during the read was taken as loaded: {again}")
