"""The live stage: opened once with its edits layer composed over it, changed by deltas and
by layer files edited on disk, read into a new scene at each revision.

USD stages are not safe to edit from several threads, so every call that touches USD
(deltas, reloads, reading the scene, writing the result layer) runs on one thread of its
own: :meth:`LiveStage.call` from threads, :meth:`LiveStage.acall` from the event loop.
"""
from __future__ import annotations

import asyncio
import functools
import hashlib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from pxr import Sdf, Tf

from ..delta.apply import apply_deltas
from ..delta.assets import layer_problems, stage_variables
from ..delta.edits import open_edits_layer, open_with_edits, revision_of, save_edits
from ..delta.effect import Effect, classify
from ..delta.notices import ChangedPaths
from ..delta.protocol import DeltaError, Problem
from ..errors import LumitraceError, StageError
from ..filenames import RESULT_LAYER_SUFFIX, edits_layer_path
from ..digests import readable_digest as file_digest
from ..publish.sublayer import RootEdit
from ..scene import Scene
from ..stage import validate
from ..stage.diagnostics import tf_message
from ..stage.reader import scene_from_stage
from ..stage.reuse import ReadCache
from ..trace.profiles import profile_table
from .state import ServiceState
from .transforms import part_transforms


class LayerUnreadable(LumitraceError):
    """A layer file could not be read (perhaps half-written by a program saving it, or
    gone): the caller retries, and keeps the last good revision meanwhile. ``path`` is the
    file."""

    def __init__(self, message: str, path: Path):
        super().__init__(message, str(path))
        self.path = path


@dataclass(frozen=True)
class Revision:
    """One state of the live stage: its number, scene and the effect of reaching it."""

    number: int
    scene: Scene
    effect: Effect
    source: str  # "start", "delta" or "file"
    layers: tuple[str, ...] = ()  # the layer files whose edit made it
    #: per part path, its local transform as the editor shows it
    #: (:func:`~lumitrace.serve.transforms.part_transforms`), read with the scene
    transforms: dict = field(default_factory=dict, compare=False, repr=False)


def check_profiles(scene: Scene) -> None:
    """Read the IES profile of every light that has one (each file once, cached as the
    tracer will use it), so that a profile that cannot be traced is refused at the door
    (:class:`StageError` naming the light) rather than found by the engine."""
    for emitter in scene.emitters:
        if emitter.ies is None:
            continue
        try:
            profile_table(emitter.ies)
        except LumitraceError as exc:
            said = exc.message if exc.where and exc.where in exc.message else str(exc)
            raise StageError(said, emitter.path, "inputs:shaping:ies:file") from None


class LiveStage:
    """The service's stage; see the module docstring for the threading rule."""

    def __init__(self, stage_path: str | Path, luminaire: str | None = None,
                 state: ServiceState | None = None):
        self.stage_path = Path(stage_path).absolute()
        self.edits_path = edits_layer_path(self.stage_path)
        self.luminaire = luminaire
        #: where each revision handed out is recorded, so that revisions only grow
        self.state = state
        self._reads = ReadCache()  # each read hands the next what it made
        self._usd = ThreadPoolExecutor(max_workers=1, thread_name_prefix="lumitrace-usd")
        self.call(self._open)

    # -- threading ----------------------------------------------------------------------

    def call(self, fn: Callable[..., Any], *args, **kwargs) -> Any:
        """Run ``fn`` on the USD thread and wait for it (from any other thread)."""
        return self._usd.submit(fn, *args, **kwargs).result()

    async def acall(self, fn: Callable[..., Any], *args, **kwargs) -> Any:
        """Run ``fn`` on the USD thread without blocking the event loop."""
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._usd, functools.partial(fn, *args, **kwargs))

    def close(self) -> None:
        self.call(self._close)
        self._usd.shutdown(wait=True)

    # -- on the USD thread --------------------------------------------------------------

    def _open(self) -> None:
        if not self.stage_path.is_file():
            raise StageError("stage file not found", str(self.stage_path))
        validate.check_layer_file(self.stage_path)
        self.edits = open_edits_layer(self.edits_path)
        root = Sdf.Layer.FindOrOpen(str(self.stage_path))
        if root is not None:  # else open_with_edits says why it cannot be opened
            self._check_folder_rule(self.edits, root)
        self.stage = open_with_edits(self.stage_path, self.edits)
        self.changes = ChangedPaths(self.stage)
        self.scene = scene_from_stage(self.stage, self.luminaire, cache=self._reads)
        self.revision = revision_of(self.edits)
        if self.state is not None:
            self.revision = self.state.start_revision(self.revision,
                                                      self.scene.content_hash())
            self._record(self.revision, self.scene)
        self.known: dict[Path, str | None] = {}
        #: watched files reported gone, unreadable or garbage: when one is back, it is
        #: read again (and is a revision) even if it holds what it held before
        self.troubled: set[Path] = set()
        self._remember_files()

    def _close(self) -> None:
        self.changes.close()

    def _check_folder_rule(self, edits: Sdf.Layer, root: Sdf.Layer) -> None:
        """Raise :class:`StageError` when ``edits`` (the edits layer, perhaps as saved on
        disk) names an asset that resolves outside the stage's folder, its expressions
        evaluated with ``root``'s variables: composing it would open that file."""
        problems = layer_problems(edits, self.stage_path.parent.resolve(),
                                  stage_variables(root=root))
        if problems:
            where, why = problems[0]
            raise StageError(why, f"{self.edits_path} {where}")

    def _check_saved_edits(self, changed: set[Path]) -> None:
        """The folder rule on the edits layer and root layer as saved on disk, before
        either is reloaded (a file that cannot be opened is left to the reload)."""
        if not changed & {self.edits_path, self.stage_path}:
            return

        def saved(path: Path, current: Sdf.Layer) -> Sdf.Layer | None:
            if path not in changed:
                return current
            try:
                return Sdf.Layer.OpenAsAnonymous(str(path))
            except Tf.ErrorException:
                return None
        edits = saved(self.edits_path, self.edits)
        root = saved(self.stage_path, self.stage.GetRootLayer())
        if edits is not None and root is not None:
            self._check_folder_rule(edits, root)

    def layer_files(self) -> set[Path]:
        """Files on disk of the layers the stage uses (root, sublayers, references,
        payloads, the edits layer), our result layer left out."""
        files = set()
        for layer in self.stage.GetUsedLayers():
            if layer.anonymous or not layer.realPath:
                continue
            path = Path(layer.realPath).absolute()
            if not path.name.endswith(RESULT_LAYER_SUFFIX):
                files.add(path)
        files.add(self.edits_path)
        return files

    def asset_files(self) -> set[Path]:
        """Files the scene's lights read besides the layers: IES profiles, ray files."""
        return {Path(f).absolute() for e in self.scene.emitters
                for f in ((e.ies.file,) if e.ies is not None else ()) + (
                    (e.rays,) if e.rays is not None else ())}

    def _remember_files(self) -> None:
        """Know the content of every file the stage now uses. A file known already keeps
        the digest of what was loaded from it: a save that lands while the scene is read
        must stay news to the watcher (digested from the disk now, it would pass for the
        content loaded, and be lost). A file newly used is digested as it is."""
        files = self.layer_files() | self.asset_files()
        self.known = {p: self.known[p] if p in self.known else file_digest(p) for p in files}

    def folders(self) -> set[Path]:
        """The folders to watch (those of :meth:`layer_files` and :meth:`asset_files`)."""
        return {p.parent for p in self.layer_files() | self.asset_files()}

    def start(self) -> Revision:
        """The revision the service starts from (the edits layer's last one)."""
        return Revision(self.revision, self.scene, Effect("topology"), "start",
                        transforms=self.call(self._transforms, self.scene))

    def apply(self, deltas: list[dict], base_revision: int | None = None) -> Revision:
        """Apply a batch of deltas (all or none), persist the edits layer durably and read
        the new scene. Raises :class:`DeltaError` with every problem; nothing changes then."""
        if base_revision is not None and base_revision != self.revision:
            raise DeltaError([Problem("/base_revision", f"the service is at revision "
                                      f"{self.revision}, not {base_revision}")], 409)
        backup = self.edits.ExportToString()
        self.changes.take()
        apply_deltas(self.stage, self.edits, deltas, self.stage_path.parent)
        try:
            scene = scene_from_stage(self.stage, self.luminaire, cache=self._reads)
            check_profiles(scene)
        except StageError as exc:
            self.edits.ImportFromString(backup)
            raise DeltaError([Problem(exc.where or "/", exc.message if not exc.prop else
                                      f"{exc.prop}: {exc.message}")], 422) from None
        revision = self.revision + 1
        try:
            save_edits(self.edits, revision)
        except OSError as exc:
            self.edits.ImportFromString(backup)
            raise DeltaError([Problem(str(self.edits_path), f"cannot save the edits layer: "
                                      f"{exc.strerror or exc}")], 507) from None
        self.known[self.edits_path] = file_digest(self.edits_path)
        self._record(revision, scene)
        effect = classify(self.scene, scene, self.changes.take())
        self.scene, self.revision = scene, revision
        for path in self.asset_files():  # a light's file a delta named: watched from now on
            self.known.setdefault(path, file_digest(path))
        return Revision(revision, scene, effect, "delta",
                        transforms=self._transforms(scene))

    def reload(self, paths: set[Path]) -> Revision | None:
        """Reload the used layers among ``paths`` whose content changed (``force``: USD
        compares modification times only), and those back after being reported gone or
        unreadable (:meth:`trouble`), and read the new scene; None when nothing the stage
        uses changed (our own writes, other files). Raises :class:`LayerUnreadable` for a
        file that cannot be read now (or is gone), :class:`StageError` for a bad new
        scene."""
        files = self.layer_files()
        changed = self._changed_files(paths, files | self.asset_files())
        if not changed:
            return None
        self.changes.take()
        for path, _ in changed:
            if path in files:  # a light's file is read again with the scene below
                try:
                    validate.check_layer_file(path)
                except StageError as exc:
                    raise LayerUnreadable(exc.message, path) from None
        self._check_saved_edits({p for p, _ in changed})
        for path, _ in changed:
            if path in files:
                self._reload_layer(path)
        for path, digest in changed:
            self.known[path] = digest
        if self.edits_path in {p for p, _ in changed}:
            self.revision = max(self.revision, revision_of(self.edits))
        scene = scene_from_stage(self.stage, self.luminaire, cache=self._reads)
        check_profiles(scene)
        self.troubled.difference_update(p for p, _ in changed)
        effect = classify(self.scene, scene, self.changes.take())
        self.revision += 1
        self._record(self.revision, scene)
        self.scene = scene
        self._remember_files()  # new sublayers, references or light files are watched now
        return Revision(self.revision, scene, effect, "file",
                        tuple(str(p) for p, _ in changed), self._transforms(scene))

    def _transforms(self, scene: Scene) -> dict:
        """The parts' local transforms as the editor shows them, read now (on the USD
        thread, with the scene they belong to)."""
        return part_transforms(self.stage, scene.parts, scene.time_code)

    def _record(self, revision: int, scene: Scene) -> None:
        """Record a revision handed out (a restarted service goes on above it)."""
        if self.state is not None:
            self.state.record_revision(revision, scene.content_hash())

    def _changed_files(self, paths: set[Path], watched: set[Path]) -> list[tuple[Path, str]]:
        """The watched files among ``paths`` (all of them once one was in trouble) whose
        content is new or that are back from trouble, with their digests. Raises
        :class:`LayerUnreadable` for a watched file that is gone or cannot be read."""
        asked = {Path(p).absolute() for p in paths}
        if self.troubled & watched:
            asked |= watched  # edits that came while one was gone are not missed
        changed, gone = [], []
        for path in sorted(asked & watched):
            digest = file_digest(path)
            if digest is None:
                if self.known.get(path) is not None or path in self.troubled:
                    gone.append(path)
            elif digest != self.known.get(path) or path in self.troubled:
                changed.append((path, digest))
        if gone and not changed:
            raise LayerUnreadable("is gone or cannot be read", gone[0])
        return changed

    def _reload_layer(self, path: Path) -> None:
        """Reload one used layer from its file (:class:`LayerUnreadable` if it cannot)."""
        layer = Sdf.Layer.Find(str(path))
        if layer is None:
            return
        try:
            ok = layer.Reload(force=True)
        except Tf.ErrorException as exc:
            raise LayerUnreadable(f"cannot be read: {tf_message(exc)}", path) from None
        if not ok:
            raise LayerUnreadable("cannot be read", path)

    def trouble(self, path: Path) -> None:
        """Note a watched file reported gone, unreadable or garbage: once it is readable
        again, it is read anew and makes a revision, even with its old content, so that
        the results and ``last_error`` recover without another edit."""
        self.troubled.add(Path(path).absolute())

    def write(self, write: Callable[[], Any]) -> Any:
        """Run ``write`` (publishing outputs, which may add the result sublayer to the root
        layer) and take note of what it did to the root layer (:meth:`_note_root_edit`)."""
        outcome = write()
        if isinstance(outcome, RootEdit):
            self._note_root_edit(outcome)
        return outcome

    def _note_root_edit(self, edit: RootEdit) -> None:
        """Our own write of the root layer is known content (the watcher skips it) only
        when what it started from is what the service last loaded: a save by anyone else,
        read by the edit or landing after it, leaves a file unlike what we know, and the
        watcher makes it a revision. Content is compared, never timing."""
        root = self.stage_path
        if edit.wrote is None or edit.read is None:
            return
        if hashlib.sha256(edit.read).hexdigest() == self.known.get(root):
            self.known[root] = hashlib.sha256(edit.wrote).hexdigest()
