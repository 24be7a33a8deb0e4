"""References the live view compares the current design with: a target photometric file
(IES or EULUMDAT) made into a frame like the preview's (its grid, its map on the preview's
lat-long raster, its figures; no standard errors), and the last preview frame of each
recent revision, kept so that a designer can pin any of them."""
from __future__ import annotations

import collections
import threading
from typing import Any

import numpy as np

from ..photometry.target import read_target, target_figures
from .viewer import LATLONG_C, LATLONG_GAMMA, frame_bytes

#: Revisions whose last preview frame is kept (the newest ones).
KEPT_REVISIONS = 64
#: Largest photometric file accepted as a reference (characters).
MAX_FILE_CHARS = 4 << 20


def reference_frame(name: str, text: str) -> bytes:
    """The frame of a photometric file's distribution (raises
    :class:`~lumitrace.errors.LumitraceError` naming the file for text it cannot use)."""
    target = read_target(name, text)
    full = target.grid.full()
    rows = full.at(LATLONG_C)  # (C, file gammas), linear in C
    latlong = np.stack([np.interp(LATLONG_GAMMA, full.gamma, r) for r in rows], axis=1)
    header = {"kind": "file", "name": target.name, "format": target.format,
              "revision": None, "photons": None, "lamp_lumens": target.lamp_lumens,
              "symmetry": target.grid.symmetry, "c": full.c.tolist(),
              "gamma": full.gamma.tolist(),
              "latlong": {"c": LATLONG_C.tolist(), "gamma": LATLONG_GAMMA.tolist()},
              "figures": _plain(target_figures(target)),
              "units": {"map": "cd", "grid": "cd", "sigma": "cd"}}
    return frame_bytes(header, {"filtered": latlong, "raw": latlong, "grid": full.candela,
                                "sigma": np.zeros_like(full.candela)})


def _plain(figures: dict) -> dict:
    return {k: (None if v is None else float(v)) for k, v in figures.items()}


class KeptFrames:
    """The last preview frame of each of the newest :data:`KEPT_REVISIONS` revisions
    (the one of most photons), with a short summary of each."""

    def __init__(self, size: int = KEPT_REVISIONS):
        self._size = size
        self._lock = threading.Lock()
        self._frames: collections.OrderedDict[int, tuple[dict, bytes]] = \
            collections.OrderedDict()

    def keep(self, header: dict, data: bytes) -> None:
        """Keep ``data`` (a preview frame whose header is ``header``) for its revision,
        unless a frame of more photons is kept for it."""
        revision = int(header["revision"])
        summary = {"revision": revision, "photons": header["photons"],
                   "iterations": header.get("iterations"),
                   "relative_error": header.get("relative_error"),
                   "photometry_error": header["figures"].get("photometry_error"),
                   "luminous_flux": header["figures"].get("luminous_flux")}
        with self._lock:
            old = self._frames.get(revision)
            if old is not None and old[0]["photons"] > summary["photons"]:
                return
            self._frames[revision] = (summary, data)
            while len(self._frames) > self._size:
                self._frames.pop(min(self._frames))

    def get(self, revision: int) -> bytes | None:
        with self._lock:
            kept = self._frames.get(revision)
        return None if kept is None else kept[1]

    def summaries(self) -> list[dict[str, Any]]:
        """The kept revisions, newest first."""
        with self._lock:
            return [s for s, _ in sorted(self._frames.values(),
                                         key=lambda x: -x[0]["revision"])]
