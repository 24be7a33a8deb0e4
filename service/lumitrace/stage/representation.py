"""lumitrace's own output in a stage is never traced.

The result layer (:mod:`lumitrace.publish.result_layer`) authors on the luminaire a variant
set ``lumitraceRepresentation``: ``geometry`` (the modelled luminaire, the default) and
``photometric`` (the traced emitters deactivated, one IES-shaped DiskLight
``lumitracePhotometricLight`` in their place). Tracing that stand-in would measure
lumitrace's own result. So:

- when the composed stage selects ``photometric`` (in any layer), the luminaire is read with
  the selection forced to ``geometry``: authored for the read in the stage's session layer
  (the strongest layer) and taken out again afterwards, so no layer on disk and none of
  the caller's opinions change; a stage without an editable session layer is read through a
  second stage over the same layers, with a session layer of its own;
- a light named ``lumitracePhotometricLight`` directly under the luminaire is never traced,
  whatever selected it.
"""
from __future__ import annotations

from contextlib import contextmanager
from typing import Callable, Iterator

from pxr import Sdf, Usd

from ..errors import StageError

#: The names the result layer writes (:mod:`lumitrace.publish.result_layer`; the stage
#: reader comes before publishing in the data flow, so it keeps its own copy).
REPRESENTATION = "lumitraceRepresentation"
GEOMETRY = "geometry"
PHOTOMETRIC = "photometric"
PHOTOMETRIC_LIGHT = "lumitracePhotometricLight"


def is_stand_in_light(prim: Usd.Prim, root_path: Sdf.Path) -> bool:
    """Whether ``prim`` is the stand-in light of the photometric representation: named
    :data:`PHOTOMETRIC_LIGHT`, directly under the luminaire ``root_path``."""
    return prim.GetName() == PHOTOMETRIC_LIGHT and prim.GetPath().GetParentPath() == root_path


def selects_photometric(prim: Usd.Prim) -> bool:
    """Whether the composed stage selects the photometric representation on ``prim``."""
    sets = prim.GetVariantSets()
    return sets.HasVariantSet(REPRESENTATION) and \
        sets.GetVariantSelection(REPRESENTATION) == PHOTOMETRIC


@contextmanager
def modelled_luminaire(stage: Usd.Stage, root: Usd.Prim,
                       warn: Callable[[str], None]) -> Iterator[Usd.Stage]:
    """The stage to read the luminaire ``root`` from: ``stage`` itself, with the
    representation forced to ``geometry`` for as long as the context lasts when it selects
    ``photometric`` (with a warning). Prim handles taken before may be stale inside."""
    if not selects_photometric(root):
        yield stage
        return
    path = root.GetPath()
    warn(f"{path}: variant set {REPRESENTATION} selects {PHOTOMETRIC!r}, lumitrace's own "
         f"stand-in light: the modelled luminaire is traced instead (read with "
         f"{REPRESENTATION} = {GEOMETRY!r})")
    session = stage.GetSessionLayer()
    if session is None or not session.permissionToEdit:
        stage = _stage_with_own_session(stage)
        session = stage.GetSessionLayer()
    with _selection_in(session, path, REPRESENTATION, GEOMETRY):
        prim = stage.GetPrimAtPath(path)
        if not prim or prim.GetVariantSets().GetVariantSelection(REPRESENTATION) != GEOMETRY:
            raise StageError(f"cannot select the {GEOMETRY!r} variant of {REPRESENTATION} "
                             "to read the modelled luminaire", str(path), "variants")
        yield stage


def _stage_with_own_session(stage: Usd.Stage) -> Usd.Stage:
    """A second stage over the layers of ``stage`` (same mask and load rules) whose session
    layer is a new anonymous one, sublayering the original session layer if any."""
    session = Sdf.Layer.CreateAnonymous("lumitrace-session.usda")
    original = stage.GetSessionLayer()
    if original is not None:
        session.subLayerPaths.append(original.identifier)
    other = Usd.Stage.OpenMasked(stage.GetRootLayer(), session, stage.GetPathResolverContext(),
                                 stage.GetPopulationMask(), Usd.Stage.LoadNone)
    other.SetLoadRules(stage.GetLoadRules())
    return other


@contextmanager
def _selection_in(layer: Sdf.Layer, path: Sdf.Path, variant_set: str,
                  selection: str) -> Iterator[None]:
    """Author ``variant_set = selection`` on ``path`` in ``layer`` for the duration of the
    context, then put back what the layer held: its own selection, if it had one, and no
    prim spec the edit had to create."""
    created = []  # prim specs the edit creates, innermost first
    p = path
    while not p.IsAbsoluteRootPath() and not layer.GetPrimAtPath(p):
        created.append(p)
        p = p.GetParentPath()
    spec = layer.GetPrimAtPath(path)
    before = spec.variantSelections[variant_set] \
        if spec and variant_set in spec.variantSelections else None
    with Sdf.ChangeBlock():
        spec = Sdf.CreatePrimInLayer(layer, path)
        spec.variantSelections[variant_set] = selection
    try:
        yield
    finally:
        with Sdf.ChangeBlock():
            spec = layer.GetPrimAtPath(path)
            if spec:
                if before is None:
                    if variant_set in spec.variantSelections:
                        del spec.variantSelections[variant_set]
                else:
                    spec.variantSelections[variant_set] = before
            for p in created:
                spec = layer.GetPrimAtPath(p)
                if not spec or not spec.IsInert():
                    break  # someone else has authored on it meanwhile: keep it
                parent = p.GetParentPath()
                if parent.IsAbsoluteRootPath():
                    del layer.rootPrims[p.name]
                else:
                    del layer.GetPrimAtPath(parent).nameChildren[p.name]
