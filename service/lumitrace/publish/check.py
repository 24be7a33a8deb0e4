"""Whether a stage's composed results are current: what ``lumitrace check`` reports, and the
opinions a trace refuses to hide its new results under.

A result is current when the composed ``lumitrace:result:sceneHash`` on the luminaire prim
equals the hash of the scene as it composes now, and every result attribute comes from a
result layer (not from stronger opinions left, say, by flattening a stage on publish).

A run killed while it published (SIGKILL or a crash after its commit point: the journal
still names files to rename) leaves the files of two runs side by side. Before judging,
the check finishes that publishing as the next ``trace`` would (under the stage's
publishing lock, :func:`lumitrace.publish.transaction.recover`), and judges the set it
completes; where it cannot (a journal another user's run left, a folder it cannot write
in), its verdict is ``interrupted``, never ``current``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import OutputError
from ..filenames import RESULT_LAYER_SUFFIX, output_names, result_layer_path, stage_name
from .ownership import belongs_to, recorded_stage
from ..schema import RESULT_PREFIX
from .result_layer import REPRESENTATION

#: Exit statuses: results current (and converged), stale or missing, current but the
#: target error not reached, a publishing interrupted that the check could not finish.
CURRENT, STALE, NOT_CONVERGED, INTERRUPTED = 0, 1, 3, 4


def _is_result_layer(layer) -> bool:
    return (layer.realPath or layer.identifier).endswith(RESULT_LAYER_SUFFIX)


def result_opinion_prims(layer) -> list[str]:
    """Root prims of ``layer`` (an Sdf layer) holding ``lumitrace:result:*`` opinions."""
    return [str(spec.path) for spec in layer.rootPrims
            if any(name.startswith(RESULT_PREFIX) for name in spec.properties.keys())]


def may_hold_results(layer_path: str | Path) -> bool:
    """Whether a root layer may hold ``lumitrace:result:*`` opinions: False for ``.usda``
    text in which the namespace appears nowhere (read without USD), True otherwise (USD
    must look)."""
    try:
        with open(layer_path, "rb") as f:
            data = f.read()
    except OSError:
        return True
    return not data.startswith(b"#usda") or RESULT_PREFIX.encode() in data


def strip_result_opinions(stage_path: str | Path) -> list[str]:
    """Remove the ``lumitrace:result:*`` opinions and the representation variant set that
    flattening a stage with its results left in its root layer, and save it; returns the
    prims cleaned. The stage's own content is not touched."""
    if not may_hold_results(stage_path):
        return []
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(str(stage_path))
    prims = result_opinion_prims(layer) if layer is not None else []
    for path in prims:
        spec = layer.GetPrimAtPath(path)
        for name in [n for n in spec.properties.keys() if n.startswith(RESULT_PREFIX)]:
            spec.RemoveProperty(spec.properties[name])
        if REPRESENTATION in spec.variantSets:
            spec.variantSetNameList.RemoveItemEdits(REPRESENTATION)
            del spec.variantSets[REPRESENTATION]
            if REPRESENTATION in spec.variantSelections:
                del spec.variantSelections[REPRESENTATION]
    if prims:
        layer.Save()
    return prims


def stronger_result_opinions(stage, prim_path: str, result_layer: Path | None = None
                             ) -> list[str]:
    """Layers of ``stage``'s root layer stack holding ``lumitrace:result:*`` opinions on
    ``prim_path`` that are stronger than the result layer (``result_layer``, or where a
    trace would sublayer it: first among the root layer's sublayers)."""
    stack = stage.GetLayerStack(includeSessionLayers=False)  # strongest first
    where = next((i for i, layer in enumerate(stack) if _is_result_layer(layer) and (
        result_layer is None or Path(layer.realPath or "") == Path(result_layer))), 1)
    out = []
    for layer in stack[:where]:
        spec = layer.GetPrimAtPath(prim_path)
        if spec and any(name.startswith(RESULT_PREFIX) for name in spec.properties.keys()):
            out.append(layer.realPath or layer.identifier)
    return out


@dataclass(frozen=True)
class Check:
    """The verdict on a stage's results: ``status`` (current, not converged, stale,
    missing), one line saying why, the exit status, and the composed figures read."""

    status: str
    message: str
    exit_status: int
    values: dict

    def as_dict(self) -> dict:
        return {"status": self.status, "message": self.message,
                "exitStatus": self.exit_status, **self.values}


def result_folders(stage_path: str | Path, results: str | Path | None = None) -> list[Path]:
    """The folders a stage's result layer may be published in: ``results`` where given,
    else the stage's own folder and those of the result layers its root layer sublayers
    (``trace --out DIR`` without ``--no-sublayer``)."""
    if results is not None:
        return [Path(results).absolute()]
    stage = Path(stage_path).absolute()
    folders = [stage.parent]
    if not stage.is_file():  # a FIFO is never opened: the reader refuses it at once
        return folders
    from pxr import Sdf, Tf

    try:
        root = Sdf.Layer.OpenAsAnonymous(str(stage), metadataOnly=True)
    except Tf.ErrorException:
        root = None
    for sub in (root.subLayerPaths if root is not None else ()):
        if sub.endswith(RESULT_LAYER_SUFFIX):
            folder = (stage.parent / sub).parent.absolute()
            if folder not in folders:
                folders.append(folder)
    return folders


def finish_interrupted(stage_path: str | Path, results: str | Path | None = None
                       ) -> tuple[list[str], str | None]:
    """Finish a publishing of the stage's results that a killed run left half done (see
    the module's note): (what was done, why a publishing is still unfinished or None)."""
    from .transaction import (DEFAULT_LOCK_WAIT, journal_is_ours, journal_path, locked,
                              recover)

    name = stage_name(stage_path)
    done: list[str] = []
    for folder in result_folders(stage_path, results):
        journal = journal_path(folder, name)
        if not journal.exists():
            continue
        try:
            with locked([folder], name, DEFAULT_LOCK_WAIT):
                if journal.exists() and not journal_is_ours(journal):
                    return done, (f"a publishing of these results was interrupted "
                                  f"({journal}), and its journal is not one this user's "
                                  "lumitrace wrote (nothing it names was touched): trace "
                                  "the stage again, as its owner")
                done += recover([folder], name, sorted(output_names(name)))
        except OutputError as exc:
            return done, f"a publishing of these results was interrupted ({journal.name} " \
                         f"in {folder}) and cannot be finished here: {exc}"
        if journal.exists():
            return done, (f"a publishing of these results was interrupted ({journal}) and "
                          f"could not be finished ({'; '.join(done)}): trace the stage again")
        from pxr import Sdf

        layer = Sdf.Layer.Find(str(folder / f"{name}{RESULT_LAYER_SUFFIX}"))
        if layer is not None:  # open in this process: read it as it is now
            layer.Reload(force=True)
    return done, None


def check_stage(stage_path: str | Path, results: str | Path | None = None) -> Check:
    """Compose ``stage_path`` and judge its results against the scene it composes now.
    ``results`` is the folder a trace wrote them to with ``--out`` (and, say,
    ``--no-sublayer``): its result layer is then composed over the stage and judged. A
    publishing that a killed run left half done is finished first (:func:`finish_interrupted`);
    where it cannot be, the verdict is ``interrupted``."""
    from pxr import Usd

    from ..stage.reader import read_stage

    done, unfinished = finish_interrupted(stage_path, results)
    if unfinished is not None:
        return Check("interrupted", unfinished, INTERRUPTED, {"recovered": done})
    scene = read_stage(stage_path)
    stage = Usd.Stage.Open(str(stage_path))
    if results is not None:
        layer = Path(results) / Path(result_layer_path(stage_path)).name
        if not layer.is_file():
            return Check("missing", f"no result layer {layer}: trace the stage with --out "
                         f"{results}", STALE, {"resultLayer": str(layer)})
        if not belongs_to(layer, Path(stage_path)):
            return Check("stale", f"{layer} holds the results of another stage "
                         f"({recorded_stage(layer) or 'unknown'})", STALE,
                         {"resultLayer": str(layer)})
        stage.GetSessionLayer().subLayerPaths.append(str(layer.absolute()))
    prim = stage.GetPrimAtPath(scene.luminaire_path)
    names = ("sceneHash", "converged", "relativeError", "relativeErrorBound", "photons",
             "photometryError", "iesFile", "targetOf", "judgedError")
    values = {}
    for name in names:
        attr = prim.GetAttribute(RESULT_PREFIX + name)
        v = attr.Get() if attr and attr.HasAuthoredValue() else None
        values[name] = v if isinstance(v, (str, int, float, bool, type(None))) else \
            getattr(v, "path", str(v))
    values["currentSceneHash"] = scene.content_hash()
    values["recovered"] = done  # an interrupted publishing finished first
    layered = results is None and any(
        _is_result_layer(layer) for layer in stage.GetLayerStack(includeSessionLayers=False))
    # opinions stronger than a result layer hide it; without one (a stage flattened with
    # its results) they are the results, judged by their hash
    stronger = stronger_result_opinions(stage, scene.luminaire_path,
                                        result_layer_path(stage_path)) if layered else []
    if values["sceneHash"] is None:
        return Check("missing", f"no results on {scene.luminaire_path}: trace the stage",
                     STALE, values)
    if stronger:
        return Check("stale", f"{', '.join(stronger)} holds lumitrace:result:* opinions "
                     f"stronger than the result layer: the composed results are not the "
                     f"last trace's (remove them)", STALE, values)
    if values["sceneHash"] != values["currentSceneHash"]:
        return Check("stale", "the stage changed since its results were traced: trace it "
                     "again", STALE, values)
    on = values["targetOf"] or "map"  # results from before the files were judged: the map
    if not values["converged"]:
        err = values["judgedError"] if values["targetOf"] else values["relativeErrorBound"]
        err = values["relativeError"] if err is None else err  # results from before the bound
        what = "the files' error" if on == "files" else "the map's error, at most"
        return Check("not converged", "the results are current but did not reach their "
                     f"target error ({what} "
                     f"{'undefined' if err is None else f'{err:.2%}'})", NOT_CONVERGED, values)
    return Check("current", f"the results are current and converged (judged on the {on})",
                 CURRENT, values)
