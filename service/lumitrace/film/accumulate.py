"""Per-emitter accumulators: photon counts per texel and the photons' fates, summed exactly.

Photons are analog (every photon of an emitter carries flux / photons), so the exact,
order-independent record of a run is integer counts; fluxes and intensities are derived
from them in float64. The map is linear in the emitters: a flux change is a rescale of
that emitter's counts, not a retrace.
"""
from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass, field

import numpy as np

from .cubemap import texel_solid_angles
from .goniometer import N_BINS, N_CELLS, Goniometer
from ..scene import Scene
from .tally import BatchTally


#: Above this many bytes of dense per-emitter counts (emitters x 2 x texels x 8), each
#: emitter keeps only its nonzero texels: memory then follows the photons, not the number
#: of emitters (10,000 lights at resolution 64 would need 3.9 GB dense).
DENSE_COUNTS_BYTES = 256 << 20


#: Versions of counts (see :attr:`Accumulator.version`).
_VERSIONS = itertools.count(1)


class SparseCounts:
    """An emitter's (2, texels) int64 counts kept as its nonzero texels: sorted texel
    indices ``idx`` and their counts ``val`` (2, len(idx)). Exact, like the dense array."""

    __slots__ = ("ntex", "idx", "val")

    def __init__(self, ntex: int, idx: np.ndarray | None = None,
                 val: np.ndarray | None = None):
        self.ntex = ntex
        self.idx = np.zeros(0, np.int64) if idx is None else idx
        self.val = np.zeros((2, 0), np.int64) if val is None else val

    @classmethod
    def from_dense(cls, dense: np.ndarray) -> "SparseCounts":
        idx = np.flatnonzero(dense.any(axis=0))
        return cls(dense.shape[1], idx, dense[:, idx].copy())

    def copy(self) -> "SparseCounts":
        return SparseCounts(self.ntex, self.idx.copy(), self.val.copy())

    def sum(self, axis=None):
        if axis is None:
            return self.val.sum()
        return self.dense().sum(axis=axis)

    def dense(self) -> np.ndarray:
        out = np.zeros((2, self.ntex), np.int64)
        out[:, self.idx] = self.val
        return out

    def covers(self, other) -> bool:
        """Whether every count of ``other`` (dense or sparse) is at most this one's."""
        nz, v = _nonzero(other)
        pos = np.searchsorted(self.idx, nz)
        if not (pos < len(self.idx)).all() or not np.array_equal(self.idx[pos], nz):
            return False
        return bool((v <= self.val[:, pos]).all())

    def add(self, other, sign: int) -> None:
        """Add (sign 1) or subtract (sign -1) counts, dense or sparse."""
        nz, v = _nonzero(other)
        if not len(nz):
            return
        pos = np.searchsorted(self.idx, nz)
        old = pos < len(self.idx)
        old[old] = self.idx[pos[old]] == nz[old]
        if not old.all():  # bins this emitter had not hit yet: insert them (zero) first
            new = ~old
            self.idx = np.insert(self.idx, pos[new], nz[new])
            self.val = np.insert(self.val, pos[new], 0, axis=1)
            pos = np.searchsorted(self.idx, nz)
        self.val[:, pos] += sign * v
        if sign < 0:
            keep = self.val.any(axis=0)
            if not keep.all():
                self.idx, self.val = self.idx[keep], self.val[:, keep]


class EscapeBins:
    """A batch's goniophotometer counts as its escapes' flat bins (``bin + n * half``, a
    photon's each), as the tracer writes them: added to dense counts where they fall, not
    first counted into a (2, n) array of their own (its count and add took 3-4 ms a batch
    of 2^18 photons, most of it a fresh 3.4 MB array; the scatter takes 1-2)."""

    __slots__ = ("n", "bins")

    def __init__(self, n: int, bins: np.ndarray):
        self.n, self.bins = n, bins

    def counts(self):
        """The same counts, dense or sparse (see :func:`counts_of`)."""
        return counts_of(self.bins, self.n)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        """The same counts as a dense (2, n) array (numpy's functions read this)."""
        c = self.counts()
        c = c.dense() if isinstance(c, SparseCounts) else c
        return c if dtype is None else c.astype(dtype)


def _scatter_numpy(flat: np.ndarray, bins: np.ndarray, sign: int) -> None:
    np.add.at(flat, bins, sign)


#: Adds ``sign`` at ``flat[bins]``, each bin once per occurrence: numpy's, until the
#: tracer's compiled kernels are loaded (:func:`use_compiled_scatter`).
_scatter = _scatter_numpy


def use_compiled_scatter(add_bins) -> None:
    """Add escape bins with ``add_bins(flat, bins, sign)`` from now on (the tracer's
    compiled kernels call this)."""
    global _scatter
    _scatter = add_bins


def _nonzero(counts) -> tuple[np.ndarray, np.ndarray]:
    """(texel indices, counts (2, k)) of the nonzero texels of dense or sparse counts (or
    escape bins)."""
    if isinstance(counts, EscapeBins):
        counts = counts.counts()
    if isinstance(counts, SparseCounts):
        return counts.idx, counts.val
    nz = np.flatnonzero(counts.any(axis=0))
    return nz, counts[:, nz]


def compact(counts, photons: int | None = None):
    """A batch's dense counts, or their sparse form when that is much smaller (a batch of
    a few photons in a large map): what worker processes send back. A batch of
    ``photons`` that could fill a quarter of the bins stays dense without a look (a scan
    of every bin per batch: 2% of a 10M-photon run without geometry)."""
    if counts is None or isinstance(counts, (SparseCounts, EscapeBins)):
        return counts  # (escape bins: at most 16 bytes a photon, dense counts' size or less)
    if photons is not None and 4 * photons >= counts.shape[1]:
        return counts
    return SparseCounts.from_dense(counts) if \
        np.count_nonzero(counts.any(axis=0)) * 4 < counts.shape[1] else counts


def counts_of(bins: np.ndarray, n: int, weights: np.ndarray | None = None):
    """(2, n) counts of the flat indices ``bins`` (bin + n * half), or sums of integer
    ``weights`` (int64, exact) at them: dense, or sparse when they are few against ``n``
    (a small batch must not fill and send a large array)."""
    if len(bins) * 8 >= n:
        if weights is None:
            return np.bincount(bins, minlength=2 * n).reshape(2, n)
        # float sums of integers are exact below 2**53: a batch stays far below
        return np.rint(np.bincount(bins, weights=weights, minlength=2 * n)).astype(
            np.int64).reshape(2, n)
    half, b = np.divmod(bins, n)
    idx, inv = np.unique(b, return_inverse=True)
    val = np.zeros((2, len(idx)), np.int64)
    np.add.at(val, (half, inv), 1 if weights is None else weights)
    return SparseCounts(n, idx, val)



def _add_counts(target, counts, sign: int) -> None:
    """Add (sign 1) or subtract (sign -1) dense or sparse ``counts`` (or escape bins)
    into ``target``."""
    if isinstance(counts, EscapeBins):
        if isinstance(target, np.ndarray) and target.flags.c_contiguous:
            _scatter(target.reshape(-1), counts.bins, sign)  # (a view: written in place)
            return
        counts = counts.counts()
    if isinstance(target, SparseCounts):
        target.add(counts, sign)
    elif isinstance(counts, SparseCounts):
        target[:, counts.idx] += sign * counts.val
    elif sign > 0:
        target += counts
    else:
        target -= counts


def _add_tristimulus(out: np.ndarray, t: "EmitterTally", counts: np.ndarray, at, w: float,
                     first: int, half: int | None) -> None:
    """Add an emitter's Y (``counts`` at ``at``, photon flux ``w``) and its X and Z to
    ``out`` (3, n): its spectral tallies ``t.xz[first]``, ``t.xz[first + 1]`` where it has
    them, else its light's X/Y and Z/Y times its counts."""
    from ..scene.spectra import FIXED_POINT

    out[1, at] += counts * w
    for row, k in ((0, 0), (2, 1)):
        if t.xz is None:
            out[row, at] += counts * (w * t.ratios[k])
        else:
            q, qidx = _half(t.xz[first + k], half)
            out[row, slice(None) if qidx is None else qidx] += q * (w / FIXED_POINT)


def _half(counts, half: int | None) -> tuple[np.ndarray, np.ndarray | None]:
    """(values, texel indices or None for dense) of the counts of a half, or both."""
    if isinstance(counts, SparseCounts):
        v = counts.val.sum(axis=0) if half is None else counts.val[half]
        return v, counts.idx
    return (counts.sum(axis=0) if half is None else counts[half]), None


@dataclass
class EmitterTally:
    """Running totals of one emitter's photons."""

    path: str
    flux: float
    photons: int = 0
    counts: np.ndarray = field(default=None, repr=False)
    cells: np.ndarray = field(default=None, repr=False)  # the goniophotometer's counts
    absorbed: int = 0
    cut: int = 0
    segments: int = 0
    #: a spectral scene's X and Z tallies: x, z per texel, x, z per C-gamma cell (see
    #: :class:`~lumitrace.film.tally.BatchTally`); None otherwise
    xz: list | None = field(default=None, repr=False)
    #: (X/Y, Z/Y) of the light's spectrum: its colour where no surface changes it
    ratios: tuple = (0.0, 0.0)

    @property
    def escaped(self) -> int:
        return int(self.counts.sum())

    @property
    def photon_flux(self) -> float:
        """Flux each photon carries (lm)."""
        return self.flux / self.photons if self.photons else 0.0


class Accumulator:
    """Sums batch tallies per emitter and turns them into intensities (cd) and fluxes (lm)."""

    def __init__(self, scene: Scene, resolution: int, goniometer: Goniometer | None = None):
        """Zero counts for ``scene``'s emitters in a cube map of ``resolution`` texels a
        side; ``goniometer`` is the one the tracer counts with (default: the scene's)."""
        self.resolution = int(resolution)
        self.goniometer = goniometer or Goniometer.of(scene)
        ntex = 6 * self.resolution * self.resolution
        sparse = len(scene.emitters) * 2 * (ntex + N_BINS) * 8 > DENSE_COUNTS_BYTES
        new = (lambda n: SparseCounts(n)) if sparse else \
            (lambda n: np.zeros((2, n), np.int64))  # noqa: E731
        #: the scene's colour mode (:attr:`lumitrace.scene.Scene.colour`)
        self.colour = scene.colour
        self.emitters = [EmitterTally(e.path, e.flux, counts=new(ntex), cells=new(N_BINS),
                                      xz=[new(ntex), new(ntex), new(N_CELLS), new(N_CELLS)]
                                      if self.colour == "spectral" else None)
                         for e in scene.emitters]
        self.set_colours(scene)
        self._solid_angles = texel_solid_angles(self.resolution)
        #: surface hits per part since the start (None once a batch without them, or a
        #: removal, makes the count unknown): parts no photon reaches are reported
        self.part_hits: np.ndarray | None = np.zeros(len(scene.parts), np.int64)
        self.parts = tuple(scene.parts)
        # a mesh light's own surface: its photons leave it, none need reach it
        self.emitting_parts = frozenset(e.path.split("[")[0] for e in scene.emitters
                                        if e.kind == "mesh")
        #: a new value (unique in the process) at every batch added or removed: equal
        #: versions are the same counts (an accumulator's snapshots copy it), whatever the
        #: lights' fluxes
        self.version = next(_VERSIONS)
        #: a new value (unique in the process) whenever counts are taken out (a retrace):
        #: counts of one lineage hold every photon of earlier counts of it, as traced
        self.lineage = next(_VERSIONS)

    def set_colours(self, scene: Scene) -> None:
        """Take each light's colour (X/Y, Z/Y of its spectrum, D65 without one) from
        ``scene``: a light's colour edit in a scene of neutral surfaces retraces nothing."""
        if self.colour == "none":
            return
        from ..scene.spectra import chromaticity_ratios, d65

        for t, e in zip(self.emitters, scene.emitters):
            t.ratios = chromaticity_ratios(e.spectrum if e.spectrum else d65())

    def unreached_parts(self) -> list[str] | None:
        """Parts no traced photon hit (fully enclosed, behind an absorber, hidden), or None
        when that is not known; a mesh light's own surface, which its photons leave, is not
        reported."""
        if self.part_hits is None:
            return None
        return [p for p, n in zip(self.parts, self.part_hits)
                if n == 0 and p not in self.emitting_parts]

    def add(self, batch: BatchTally) -> None:
        """Add a batch's photons (integer sums: exact and order-independent)."""
        self._apply(batch, 1)

    def remove(self, batch: BatchTally) -> None:
        """Take a batch's photons out again, exactly as :meth:`add` put them in (the batch
        must have been added): the accumulator is then as if it never had been."""
        t = self.emitters[batch.emitter]
        if isinstance(t.counts, SparseCounts):
            covered = t.counts.covers(batch.counts)
        else:
            nz, v = _nonzero(batch.counts)
            covered = not np.any(v > t.counts[:, nz])
        if batch.photons > t.photons or not covered:
            raise ValueError(f"batch of emitter {batch.emitter} from photon {batch.start} "
                             "was not added to this accumulator")
        self.lineage = next(_VERSIONS)
        self._apply(batch, -1)

    def _apply(self, batch: BatchTally, sign: int) -> None:
        t = self.emitters[batch.emitter]
        self.version = next(_VERSIONS)
        if sign > 0 and batch.part_hits is not None and self.part_hits is not None \
                and len(batch.part_hits) == len(self.part_hits):
            self.part_hits += batch.part_hits
        else:
            self.part_hits = None
        t.photons += sign * batch.photons
        _add_counts(t.counts, batch.counts, sign)
        if batch.cells is not None:
            _add_counts(t.cells, batch.cells, sign)
        if t.xz is not None and batch.xz is not None:
            for target, part in zip(t.xz, batch.xz):
                _add_counts(target, part, sign)
        t.absorbed += sign * batch.absorbed
        t.cut += sign * batch.cut
        t.segments += sign * batch.segments

    def snapshot(self) -> "Accumulator":
        """An independent copy (counts copied): what progress callbacks and other threads
        get, so the running session never changes a map under their feet."""
        copy = Accumulator.__new__(Accumulator)
        copy.resolution = self.resolution
        copy.goniometer = self.goniometer
        copy._solid_angles = self._solid_angles
        copy.colour = self.colour
        copy.emitters = [dataclasses.replace(t, counts=t.counts.copy(), cells=t.cells.copy(),
                                             xz=None if t.xz is None else
                                             [a.copy() for a in t.xz])
                         for t in self.emitters]
        copy.part_hits = None if self.part_hits is None else self.part_hits.copy()
        copy.parts = self.parts
        copy.emitting_parts = self.emitting_parts
        copy.version = self.version
        copy.lineage = self.lineage
        return copy

    def light_state(self) -> tuple:
        """What the maps depend on besides the counts: each light's flux (lm) and colour."""
        return tuple((t.flux, tuple(np.asarray(t.ratios, np.float64).tolist()))
                     for t in self.emitters)


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
    def spread_known(self) -> bool:
        """Whether every light has the two photons its variance needs: with one, the
        result's standard errors (and so its error estimates) are undefined."""
        return all(t.photons >= 2 for t in self.emitters if t.flux > 0)

    @property
    def shape(self) -> tuple[int, int]:
        return (6 * self.resolution, self.resolution)

    def counts(self, half: int | None = None) -> np.ndarray:
        """Photons that escaped into each texel, all emitters, (6R, R) int64; ``half`` 0 or
        1 counts only that pseudo-random half of the photons."""
        out = np.zeros(self.shape[0] * self.shape[1], np.int64)
        for t in self.emitters:
            v, idx = _half(t.counts, half)
            if idx is None:
                out += v
            else:
                out[idx] += v
        return out.reshape(self.shape)

    def texel_flux(self, half: int | None = None) -> np.ndarray:
        """Flux (lm) that left the luminaire through each texel's solid angle, (6R, R).

        With ``half`` (0 or 1): the estimate from that half of the photons alone (each
        photon then carries twice its flux), an independent estimate of the same map.
        """
        flux = np.zeros(self.shape[0] * self.shape[1])
        for t in self.emitters:
            if t.photons:
                v, idx = _half(t.counts, half)
                w = t.photon_flux if half is None else 2.0 * t.photon_flux
                if idx is None:
                    flux += v * w
                else:
                    flux[idx] += v * w
        return flux.reshape(self.shape)

    def flux_variance(self) -> np.ndarray:
        """Variance (lm^2) of each texel's flux estimate, (6R, R): photons are analog, so a
        texel's count is binomial, var = sum over emitters of w^2 n (1 - n / N)."""
        var = np.zeros(self.shape[0] * self.shape[1])
        for t in self.emitters:
            if t.photons:
                v, idx = _half(t.counts, None)
                n = v.astype(np.float64)
                term = t.photon_flux ** 2 * n * (1.0 - n / t.photons)
                if idx is None:
                    var += term
                else:
                    var[idx] += term
        return var.reshape(self.shape)

    def tristimulus_flux(self, half: int | None = None) -> np.ndarray:
        """CIE X, Y, Z of the flux (lm for Y) that left through each texel, (3, 6R, R);
        ``half`` as in :meth:`texel_flux`. Y is :meth:`texel_flux`."""
        out = np.zeros((3, self.shape[0] * self.shape[1]))
        for t in self.emitters:
            if not t.photons:
                continue
            w = t.photon_flux if half is None else 2.0 * t.photon_flux
            v, idx = _half(t.counts, half)
            _add_tristimulus(out, t, v, slice(None) if idx is None else idx, w, 0, half)
        return out.reshape(3, *self.shape)

    def cell_tristimulus(self, half: int | None = None) -> np.ndarray:
        """CIE X, Y, Z of the flux (lm for Y) counted in each C-gamma cell of the
        goniophotometer, (3, N_CELLS); ``half`` as in :meth:`emitter_cells`."""
        out = np.zeros((3, N_CELLS))
        for t in self.emitters:
            if not t.photons:
                continue
            w = t.photon_flux if half is None else 2.0 * t.photon_flux
            v, idx = _half(t.cells, half)
            if idx is None:
                v, idx = v[:N_CELLS], np.arange(N_CELLS)
            else:
                v, idx = v[idx < N_CELLS], idx[idx < N_CELLS]
            _add_tristimulus(out, t, v, idx, w, 2, half)
        return out

    def emitter_cells(self, half: int | None = None):
        """Per emitter with photons: (photon flux (lm), photons, goniometer counts, their bin
        indices or None when dense): the counts of ``half`` 0 or 1 alone (each of its
        photons then carries twice the flux, of half as many) or of all photons."""
        for t in self.emitters:
            if not t.photons:
                continue
            v, idx = _half(t.cells, half)
            if half is None:
                yield t.photon_flux, float(t.photons), v, idx
            else:
                yield 2.0 * t.photon_flux, 0.5 * t.photons, v, idx

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


def flux_scale(before: tuple, after: tuple) -> float | None:
    """k where every light's flux in ``after`` (:meth:`Accumulator.light_state`) is k times
    its flux in ``before`` (to 1e-12) and every colour is the same; None otherwise."""
    if len(before) != len(after) or not before:
        return None
    k = after[0][0] / before[0][0] if before[0][0] > 0 else None
    if k is None or not all(c0 == c1 and f0 > 0 and abs(f1 / f0 - k) <= 1e-12 * k
                            for (f0, c0), (f1, c1) in zip(before, after)):
        return None
    return k
