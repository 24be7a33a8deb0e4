"""Image-quality figures of a cube map against a reference: PSNR and SSIM.

Both work face by face on the (6R, R) cube-map image, so no window straddles two faces.
The data range is the reference's peak intensity (cd).
"""
from __future__ import annotations

import numpy as np


def psnr(image: np.ndarray, reference: np.ndarray) -> float:
    """Peak signal-to-noise ratio (dB) of ``image`` against ``reference``, peak = max(ref)."""
    mse = float(np.mean((image - reference) ** 2))
    peak = float(reference.max())
    if mse == 0:
        return float("inf")
    return 10.0 * np.log10(peak * peak / mse)


def _box(a: np.ndarray, k: int) -> np.ndarray:
    """Mean over every k x k window fully inside each face (valid windows), per face."""
    c = np.cumsum(np.cumsum(a, axis=1), axis=2)
    c = np.pad(c, ((0, 0), (1, 0), (1, 0)))
    s = c[:, k:, k:] - c[:, :-k, k:] - c[:, k:, :-k] + c[:, :-k, :-k]
    return s / (k * k)


def ssim(image: np.ndarray, reference: np.ndarray, window: int = 7) -> float:
    """Mean structural similarity (Wang et al. 2004, uniform windows) over all faces."""
    res = reference.shape[1]
    k = min(window, res)
    x = image.reshape(6, res, res).astype(np.float64)
    y = reference.reshape(6, res, res).astype(np.float64)
    peak = float(reference.max()) or 1.0
    c1, c2 = (0.01 * peak) ** 2, (0.03 * peak) ** 2
    mx, my = _box(x, k), _box(y, k)
    vx = _box(x * x, k) - mx * mx
    vy = _box(y * y, k) - my * my
    cxy = _box(x * y, k) - mx * my
    s = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
    return float(s.mean())
