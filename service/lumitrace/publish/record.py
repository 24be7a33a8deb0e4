"""The result record: every figure of a traced result, built once from the session and
the photometry, and rendered from :data:`lumitrace.schema.RESULT_FIELDS` into the EXR
header, the result layer, the ``--json`` summary and the service's JSON."""
from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from ..film.result import TraceResult
from ..schema import RESULT_FIELDS

_FIELDS = {f.key: f for f in RESULT_FIELDS}


def input_hash(result: TraceResult) -> str:
    """Hash of the scene content and the settings that shape the map."""
    s = result.settings
    h = hashlib.sha256(result.scene.content_hash().encode())
    h.update(json.dumps({"resolution": s.resolution, "seed": s.seed, "threshold": s.threshold,
                         "max_depth": s.max_depth}, sort_keys=True).encode())
    return h.hexdigest()


class ResultRecord(Mapping[str, Any]):
    """An immutable mapping from the keys of :data:`RESULT_FIELDS` to values (None where a
    figure does not exist, such as the beam angle of a map with no beam, or the relative
    error of a map no light reached: a non-finite float is stored as None)."""

    def __init__(self, values: Mapping[str, Any]):
        unknown = sorted(set(values) - set(_FIELDS))
        if unknown:
            raise KeyError(f"unknown result field(s): {', '.join(unknown)}")
        self._values = MappingProxyType({k: defined(values.get(k)) for k in _FIELDS})

    def __getitem__(self, key: str) -> Any:
        return self._values[key]

    def __iter__(self):
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __getattr__(self, key: str) -> Any:
        try:
            return self._values[key]
        except KeyError:
            raise AttributeError(key) from None

    def layer_values(self, layer_dir: str | os.PathLike) -> dict[str, Any]:
        """Result-layer attributes (after ``lumitrace:result:``): assets relative to
        ``layer_dir``, figures that do not exist as NaN."""
        out = {}
        for f in RESULT_FIELDS:
            if f.attribute is None:
                continue
            v = self._values[f.key]
            if v is None and f.group == "colour":
                continue  # a stage without colour has no colour figures
            if f.kind == "asset":
                if v is None:
                    continue
                v = os.path.relpath(v, layer_dir)
            elif v is None and f.kind == "double":
                v = math.nan
            out[f.attribute] = v
        return out

    def exr_metadata(self) -> dict[str, Any]:
        """The figures the EXR header carries, keyed as in the header."""
        return {f.exr: self._values[f.key] for f in RESULT_FIELDS if f.exr}

    def summary(self) -> dict[str, Any]:
        """The JSON summary: plain keys, ``outputs`` and ``photometry`` nested."""
        out: dict[str, Any] = {}
        for f in RESULT_FIELDS:
            v = self._values[f.key]
            if isinstance(v, tuple):
                v = list(v)
            (out.setdefault(f.group, {}) if f.group else out)[f.key] = v
        return out


def defined(value: Any) -> Any:
    """``value``, or None where it is a float that is not a number (an undefined figure);
    in a tuple or list, each such element."""
    if isinstance(value, (float, np.floating)) and not math.isfinite(value):
        return None
    if isinstance(value, (tuple, list)):
        return type(value)(defined(v) for v in value)
    return value


def trace_figures(result: TraceResult) -> dict[str, Any]:
    """The figures of a traced session alone (no files, no photometry): photons, fluxes
    (lm), errors, settings, rates."""
    acc = result.accumulator
    f = acc.fluxes()
    secs = max(result.seconds, 1e-9)
    s = result.settings
    return {
        "stage": Path(result.scene.stage_path).name, "luminaire": result.scene.luminaire_path,
        "photons": acc.photons, "iterations": result.iterations, "seconds": result.seconds,
        "emitted_lm": f["emitted"], "escaped_lm": f["escaped"], "absorbed_lm": f["absorbed"],
        "cut_lm": f["cut"],
        "light_output_ratio": f["escaped"] / f["emitted"] if f["emitted"] else 0.0,
        "relative_error": result.relative_error,
        "relative_error_bound": result.estimate.error_bound,
        "raw_relative_error": result.estimate.raw_error,
        "filtered_relative_error": result.estimate.filtered_error,
        "converged": result.converged, "target_error": s.target_error,
        "target_of": result.judged_on, "judged_error": result.judged_error,
        "threshold": float(s.threshold), "resolution": acc.resolution, "seed": s.seed,
        "input_hash": input_hash(result), "scene_hash": result.scene.content_hash(),
        "photons_per_second": acc.photons / secs, "segments_per_second": acc.segments / secs,
        "batches_redone": result.batches_redone,
    }
