"""The folder rule: every asset path a delta, a layer fragment or the edits layer names
must resolve to a file inside the stage's folder.

What counts is what USD would open, not how the path is written: an expression
(`` `"/abs/${VAR}"` ``) is evaluated with the stage's own expression variables, the path
is anchored and resolved as USD's resolver does (search paths included), and symbolic
links and ``..`` are followed to the real file. A path that passes names a file in the
stage's folder or below it, whatever the link or variable in between.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Iterator

from pxr import Ar, Sdf, Usd


class AssetRefused(ValueError):
    """An asset path that breaks the folder rule, with the reason (``why``)."""

    def __init__(self, why: str):
        super().__init__(why)
        self.why = why


def stage_variables(stage: Usd.Stage | None = None,
                    root: Sdf.Layer | None = None) -> dict[str, Any]:
    """The expression variables USD evaluates the stage's asset paths with: those of the
    root layer, overridden by the session layer's (no other layer's count)."""
    root = root if root is not None else stage.GetRootLayer()
    variables = dict(root.expressionVariables or {})
    session = stage.GetSessionLayer() if stage is not None else None
    if session is not None:
        variables.update(session.expressionVariables or {})
    return variables


def evaluated(value: str, variables: dict[str, Any]) -> str:
    """``value`` with its variable expression evaluated (as written when it is none)."""
    if not Sdf.VariableExpression.IsExpression(value):
        return value
    result = Sdf.VariableExpression(value).Evaluate(variables)
    if result.errors:
        raise AssetRefused(f"asset path expression {value!r} cannot be evaluated: "
                           f"{'; '.join(result.errors)}")
    if not isinstance(result.value, str):
        raise AssetRefused(f"asset path expression {value!r} does not give a path")
    return result.value


def resolved_location(value: str, stage_dir: Path, variables: dict[str, Any]) -> str:
    """The real file ``value`` stands for, authored in a layer in ``stage_dir``: evaluated,
    anchored and resolved by USD's resolver, links followed (the anchored path where no
    file is there yet)."""
    if not isinstance(value, str) or not value:
        raise AssetRefused("an asset path must be a non-empty string")
    if "\x00" in value:
        raise AssetRefused(f"asset path {value!r} contains a NUL character")
    path = evaluated(value, variables)
    if not path or "\x00" in path:
        raise AssetRefused(f"asset path {value!r} evaluates to {path!r}, not a file path")
    if "://" in path or path.startswith(("@", "\\\\")) or ":" in path.split("/", 1)[0]:
        raise AssetRefused(f"asset path {value!r} must be a file path inside the stage's "
                           "folder")
    resolver = Ar.GetResolver()
    anchor = Ar.ResolvedPath(str(stage_dir / "anchor.usda"))
    identifier = resolver.CreateIdentifier(path, anchor)
    location = str(resolver.Resolve(identifier)) or identifier
    if not os.path.isabs(location):  # a search-path name that finds nothing yet
        location = str(stage_dir / location)
    return os.path.realpath(location)


def check_asset(value: str, stage_dir: Path, variables: dict[str, Any]) -> None:
    """Refuse (:class:`AssetRefused`) an asset path that does not resolve inside
    ``stage_dir`` (a real path: links followed)."""
    real = Path(resolved_location(value, stage_dir, variables))
    if real != stage_dir and stage_dir not in real.parents:
        raise AssetRefused(f"asset path {value!r} leaves the stage's folder (it resolves "
                           "outside the stage's folder)")


def layer_asset_paths(layer: Sdf.Layer) -> Iterator[tuple[str, str]]:
    """Every asset path ``layer`` authors, as written, with where: its sublayers, the
    references and payloads of its prims (in variants too), and the values and time
    samples of its asset-valued attributes."""
    for path in layer.subLayerPaths:
        yield "subLayers", path
    specs: list[Sdf.Path] = []
    layer.Traverse(Sdf.Path.absoluteRootPath, specs.append)
    for spec_path in specs:
        spec = layer.GetObjectAtPath(spec_path)
        if isinstance(spec, Sdf.VariantSpec):
            spec = spec.primSpec
        if isinstance(spec, Sdf.PrimSpec):
            for arcs in (spec.referenceList, spec.payloadList):
                for arc in arcs.GetAddedOrExplicitItems():
                    if arc.assetPath:
                        yield str(spec_path), arc.assetPath
        elif isinstance(spec, Sdf.AttributeSpec) and _is_asset(spec.typeName):
            values = [spec.default] + [layer.QueryTimeSample(spec_path, t)
                                       for t in layer.ListTimeSamplesForPath(spec_path)]
            for value in values:
                for asset in _assets_in(value):
                    yield str(spec_path), asset


def _is_asset(type_name: Sdf.ValueTypeName) -> bool:
    scalar = type_name.scalarType if type_name.isArray else type_name
    return scalar == Sdf.ValueTypeNames.Asset


def _assets_in(value: Any) -> Iterator[str]:
    """The authored paths of an asset value or array (nothing for None or a block)."""
    if isinstance(value, Sdf.AssetPath):
        yield value.path
    elif value is not None and not isinstance(value, (str, bytes)) and \
            hasattr(value, "__iter__"):
        for item in value:
            if isinstance(item, Sdf.AssetPath):
                yield item.path


def layer_problems(layer: Sdf.Layer, stage_dir: Path,
                   variables: dict[str, Any]) -> list[tuple[str, str]]:
    """(where, why) for every asset path of ``layer`` that breaks the folder rule, and for
    expression variables it authors (the stage's root layer holds those)."""
    problems = []
    if layer.expressionVariables:
        problems.append(("expressionVariables", "a layer of edits cannot set "
                         "expressionVariables: they belong to the stage's root layer"))
    for where, value in layer_asset_paths(layer):
        try:
            check_asset(value, stage_dir, variables)
        except AssetRefused as refused:
            problems.append((where, refused.why))
    return problems
