"""The zonal flux table of a datasheet: the luminaire's flux in 10 deg gamma zones from
nadir to zenith (lm), with standard errors, from the exact photon counts of the
goniometer's cells (the zone edges are cell edges: no resampling of the grid)."""
from __future__ import annotations

import math

import numpy as np

from ..film.goniometer import GAMMA_EDGES

#: Zone edges (deg from nadir).
ZONE_EDGES = tuple(float(e) for e in np.arange(0.0, 180.0 + 1e-9, 10.0))


def zonal_flux(rings: list[tuple[float, float, np.ndarray]]
               ) -> list[tuple[float, float, float, float]]:
    """(gamma from, gamma to, flux lm, standard error lm) per 10 deg zone, from the
    emitters' rings (:func:`~lumitrace.photometry.measured.emitter_rings`): each
    emitter's photons in a zone are binomial given its photons, so the variance of its
    flux there is w^2 n (1 - n / N) (w its photon flux, n the zone's count, N its
    photons); emitters are independent."""
    ends = [int(np.searchsorted(GAMMA_EDGES, e - 1e-9)) for e in ZONE_EDGES]
    flux = np.zeros(len(ZONE_EDGES) - 1)
    var = np.zeros_like(flux)
    for w, total, ring in rings:
        n = np.diff(np.concatenate([[0.0], np.cumsum(ring)])[ends])
        flux += w * n
        var += w * w * n * np.maximum(1.0 - n / total, 0.0) if total > 0 else 0.0
    return [(ZONE_EDGES[k], ZONE_EDGES[k + 1], float(flux[k]), math.sqrt(float(var[k])))
            for k in range(len(flux))]
