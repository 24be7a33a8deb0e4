"""How a photon budget is shared among emitters: in proportion to flux, so every photon
carries about the same flux, and never below a light's minimum (a light without photons
would drop its flux from the result). The split depends on the budget alone, never on
threads or batches, so the same seed gives the same photons anywhere."""
from __future__ import annotations

import math

#: Photons each emitter traces at the least: an emitter without photons would drop its
#: flux from the result (with one photon its error, and so the map's, is undefined).
MIN_EMITTER_PHOTONS = 1


def allocate(fluxes: list[float], photons: int, minimum: int = 0) -> list[int]:
    """Split ``photons`` among emitters in proportion to flux (largest remainder), each
    getting at least ``minimum`` (the others share the rest in proportion to flux); the
    split in proportion alone where it gives everyone ``minimum``."""
    if photons < minimum * len(fluxes):
        raise ValueError(f"{photons} photons cannot give {len(fluxes)} emitters "
                         f"{minimum} each")
    pinned: set[int] = set()
    while True:
        free = [i for i in range(len(fluxes)) if i not in pinned]
        share = _proportional([fluxes[i] for i in free], photons - minimum * len(pinned))
        low = {i for i, n in zip(free, share) if n < minimum}
        if not low:
            out = [minimum] * len(fluxes)
            for i, n in zip(free, share):
                out[i] = n
            return out
        pinned |= low


def _proportional(fluxes: list[float], photons: int) -> list[int]:
    """Split ``photons`` in proportion to ``fluxes`` by largest remainder."""
    if not fluxes:
        return []
    total = float(sum(fluxes))
    exact = [photons * f / total for f in fluxes]
    base = [int(math.floor(x)) for x in exact]
    rest = photons - sum(base)
    order = sorted(range(len(fluxes)), key=lambda i: (base[i] - exact[i], i))
    for i in order[:rest]:
        base[i] += 1
    return base
