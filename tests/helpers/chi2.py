"""Chi-square goodness-of-fit of direction samples against a density on the sphere.

Like Mitsuba 3's ``chi2.ChiSquareTest``: bin samples by (cos theta, phi), integrate the
density over every bin numerically, pool bins with small expectations, and return the
p-value of Pearson's statistic. A correct sampler passes with probability 1 - alpha; with a
fixed seed the outcome is deterministic.
"""
from __future__ import annotations

import numpy as np
from scipy import stats


def sphere_integral(f, n_z: int = 1024, n_phi: int = 1024) -> float:
    """Integral of ``f`` (vectorised over (N,3) unit vectors) over the sphere (midpoint rule)."""
    zs = -1 + (np.arange(n_z) + 0.5) * 2 / n_z
    ps = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    Z, P = np.meshgrid(zs, ps, indexing="ij")
    r = np.sqrt(np.maximum(0, 1 - Z**2))
    d = np.stack([r * np.cos(P), r * np.sin(P), Z], axis=-1).reshape(-1, 3)
    return float(f(d).sum() * (2 / n_z) * (2 * np.pi / n_phi))


def sphere_chi2_pvalue(dirs: np.ndarray, pdf, n_theta: int = 24, n_phi: int = 48,
                       sub: int = 8, min_expected: float = 5.0) -> float:
    """p-value that unit vectors ``dirs`` (N,3) follow ``pdf`` (per sr, sums to 1 on S^2)."""
    n = dirs.shape[0]
    z = np.clip(dirs[:, 2], -1, 1)
    phi = np.mod(np.arctan2(dirs[:, 1], dirs[:, 0]), 2 * np.pi)
    iz = np.minimum(((z + 1) / 2 * n_theta).astype(int), n_theta - 1)
    ip = np.minimum((phi / (2 * np.pi) * n_phi).astype(int), n_phi - 1)
    observed = np.bincount(iz * n_phi + ip, minlength=n_theta * n_phi).astype(float)
    # expected: midpoint rule on sub x sub points in (z, phi) per bin (dOmega = dz dphi)
    zs = -1 + (np.arange(n_theta * sub) + 0.5) * 2 / (n_theta * sub)
    ps = (np.arange(n_phi * sub) + 0.5) * 2 * np.pi / (n_phi * sub)
    Z, P = np.meshgrid(zs, ps, indexing="ij")
    r = np.sqrt(np.maximum(0, 1 - Z**2))
    d = np.stack([r * np.cos(P), r * np.sin(P), Z], axis=-1).reshape(-1, 3)
    dens = pdf(d).reshape(n_theta, sub, n_phi, sub)
    cell = (2 / (n_theta * sub)) * (2 * np.pi / (n_phi * sub))
    expected = dens.sum(axis=(1, 3)).ravel() * cell * n
    assert abs(expected.sum() / n - 1) < 1e-2, f"pdf integrates to {expected.sum() / n}"
    expected *= n / expected.sum()  # quadrature error at hard edges
    order = np.argsort(expected)
    obs_s, exp_s = observed[order], expected[order]
    # pool small bins together
    pooled_o, pooled_e, acc_o, acc_e = [], [], 0.0, 0.0
    for o, e in zip(obs_s, exp_s):
        acc_o += o
        acc_e += e
        if acc_e >= min_expected:
            pooled_o.append(acc_o)
            pooled_e.append(acc_e)
            acc_o = acc_e = 0.0
    if acc_e > 0 or acc_o > 0:
        if acc_e == 0 and acc_o > 0:
            return 0.0  # samples where the density is zero
        pooled_o[-1] += acc_o
        pooled_e[-1] += acc_e
    o = np.array(pooled_o)
    e = np.array(pooled_e)
    stat = ((o - e) ** 2 / e).sum()
    return float(stats.chi2.sf(stat, len(o) - 1))
