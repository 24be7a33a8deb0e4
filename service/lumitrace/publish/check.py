"""Whether a stage's composed results are current: what ``lumitrace check`` reports, and the
opinions a trace refuses to hide its new results under.

A result is current when the composed ``lumitrace:result:sceneHash`` on the luminaire prim
equals the hash of the scene as it composes now, and every result attribute comes from a
result layer (not from stronger opinions left, say, by flattening a stage on publish).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..filenames import RESULT_LAYER_SUFFIX, result_layer_path
from .ownership import belongs_to, recorded_stage
from ..schema import RESULT_PREFIX
from .result_layer import REPRESENTATION

#: Exit statuses: results current (and converged), stale or missing, current but the
#: target error not reached.
CURRENT, STALE, NOT_CONVERGED = 0, 1, 3


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


def check_stage(stage_path: str | Path, results: str | Path | None = None) -> Check:
    """Compose ``stage_path`` and judge its results against the scene it composes now.
    ``results`` is the folder a trace wrote them to with ``--out`` (and, say,
    ``--no-sublayer``): its result layer is then composed over the stage and judged."""
    from pxr import Usd

    from ..stage.reader import read_stage

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
