"""Per-emitter accumulators: photon counts per texel and the photons' fates, summed exactly.

Photons are analog (every photon of an emitter carries flux / photons), so the exact,
order-independent record of a run is integer counts; fluxes and intensities are derived
from them in float64. The map is linear in the emitters: a flux change is a rescale of
that emitter's counts, not a retrace.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .cubemap import texel_solid_angles
from ..scene import Scene
from .tally import BatchTally


@dataclass
class EmitterTally:
    """Running totals of one emitter's photons."""

    path: str
    flux: float
    photons: int = 0
    counts: np.ndarray = field(default=None, repr=False)
    absorbed: int = 0
    cut: int = 0
    segments: int = 0

    @property
    def escaped(self) -> int:
        return int(self.counts.sum())

    @property
    def photon_flux(self) -> float:
        """Flux each photon carries (lm)."""
        return self.flux / self.photons if self.photons else 0.0


class Accumulator:
    """Sums batch tallies per emitter and turns them into intensities (cd) and fluxes (lm)."""

    def __init__(self, scene: Scene, resolution: int):
        self.resolution = int(resolution)
        ntex = 6 * self.resolution * self.resolution
        self.emitters = [EmitterTally(e.path, e.flux, counts=np.zeros((2, ntex), np.int64))
                         for e in scene.emitters]
        self._solid_angles = texel_solid_angles(self.resolution)

    def add(self, batch: BatchTally) -> None:
        """Add a batch's photons (integer sums: exact and order-independent)."""
        self._apply(batch, 1)

    def remove(self, batch: BatchTally) -> None:
        """Take a batch's photons out again, exactly as :meth:`add` put them in (the batch
        must have been added): the accumulator is then as if it never had been."""
        t = self.emitters[batch.emitter]
        if batch.photons > t.photons or np.any(batch.counts > t.counts):
            raise ValueError(f"batch of emitter {batch.emitter} from photon {batch.start} "
                             "was not added to this accumulator")
        self._apply(batch, -1)

    def _apply(self, batch: BatchTally, sign: int) -> None:
        t = self.emitters[batch.emitter]
        t.photons += sign * batch.photons
        if sign > 0:
            t.counts += batch.counts
        else:
            t.counts -= batch.counts
        t.absorbed += sign * batch.absorbed
        t.cut += sign * batch.cut
        t.segments += sign * batch.segments

    def snapshot(self) -> "Accumulator":
        """An independent copy (counts copied): what progress callbacks and other threads
        get, so the running session never changes a map under their feet."""
        copy = Accumulator.__new__(Accumulator)
        copy.resolution = self.resolution
        copy._solid_angles = self._solid_angles
        copy.emitters = [dataclasses.replace(t, counts=t.counts.copy()) for t in self.emitters]
        return copy

    def rescale(self, emitter: int, flux: float) -> None:
        """Set an emitter's flux (lm): photons are analog, so its counts stay and every
        intensity and flux it contributes scales with it; nothing is retraced."""
        if not (flux > 0 and np.isfinite(flux)):
            raise ValueError(f"flux must be finite and positive, got {flux!r}")
        self.emitters[emitter].flux = float(flux)

    @property
    def photons(self) -> int:
        return sum(t.photons for t in self.emitters)

    @property
    def segments(self) -> int:
        return sum(t.segments for t in self.emitters)

    @property
    def shape(self) -> tuple[int, int]:
        return (6 * self.resolution, self.resolution)

    def counts(self, half: int | None = None) -> np.ndarray:
        """Photons that escaped into each texel, all emitters, (6R, R) int64; ``half`` 0 or
        1 counts only that pseudo-random half of the photons."""
        c = sum(t.counts for t in self.emitters)
        return (c.sum(axis=0) if half is None else c[half]).reshape(self.shape)

    def texel_flux(self, half: int | None = None) -> np.ndarray:
        """Flux (lm) that left the luminaire through each texel's solid angle, (6R, R).

        With ``half`` (0 or 1): the estimate from that half of the photons alone (each
        photon then carries twice its flux), an independent estimate of the same map.
        """
        flux = np.zeros(self.shape[0] * self.shape[1])
        for t in self.emitters:
            if t.photons:
                if half is None:
                    flux += t.counts.sum(axis=0) * t.photon_flux
                else:
                    flux += t.counts[half] * (2.0 * t.photon_flux)
        return flux.reshape(self.shape)

    def flux_variance(self) -> np.ndarray:
        """Variance (lm^2) of each texel's flux estimate, (6R, R): photons are analog, so a
        texel's count is binomial, var = sum over emitters of w^2 n (1 - n / N)."""
        var = np.zeros(self.shape[0] * self.shape[1])
        for t in self.emitters:
            if t.photons:
                n = t.counts.sum(axis=0).astype(np.float64)
                var += t.photon_flux ** 2 * n * (1.0 - n / t.photons)
        return var.reshape(self.shape)

    def intensity(self) -> np.ndarray:
        """Raw luminous intensity estimate (cd) per texel: texel flux / texel solid angle."""
        return self.texel_flux() / self._solid_angles

    def fluxes(self) -> dict[str, float]:
        """Emitted, escaped, absorbed and depth-cut flux (lm); emitted = the sum of the rest."""
        out = {"emitted": 0.0, "escaped": 0.0, "absorbed": 0.0, "cut": 0.0}
        for t in self.emitters:
            if not t.photons:
                continue
            w = t.photon_flux
            out["emitted"] += t.flux
            out["escaped"] += t.escaped * w
            out["absorbed"] += t.absorbed * w
            out["cut"] += t.cut * w
        return out
