"""Scalar arithmetic the photon kernels share: counter-based random numbers, vectors,
frames, the exact-reduction cosine and sine, cosine-weighted directions."""
from __future__ import annotations

import math

import numba
import numpy as np

from ..rng import _INV32, _LOW32, _M1, _M2, _S32, _S33, GOLDEN
from .jit import _ALWAYS, _INLINE

# --- counter-based random numbers (bit-identical to :mod:`lumitrace.trace.rng`, whose
# constants they are: fixed for good, as every stored map depends on them) --------------
_GOLDEN = np.uint64(GOLDEN)
_ONE = np.uint64(1)




@numba.njit(**_INLINE)
def _fmix64(k):
    k = k ^ (k >> _S33)
    k = k * _M1
    k = k ^ (k >> _S33)
    k = k * _M2
    return k ^ (k >> _S33)


@numba.njit(**_INLINE)
def _uniform_pair(base, counter):
    """Two uniforms in [0, 1) of draw ``counter`` of the photon with hash ``base``."""
    h = _fmix64(base + numba.uint64(counter + 1) * _GOLDEN)
    return float(h >> _S32) * _INV32, float(h & _LOW32) * _INV32


# --- scalar vector helpers ----------------------------------------------------------------

@numba.njit(**_INLINE)
def _rows(axes):
    """A 3 x 3 matrix (the photometric axes, a light's transform) as a 9-tuple, row by
    row: held in registers, where array reads in a loop that writes other arrays would be
    read again after every write (the arrays may alias) and keep LLVM from vectorising."""
    return (axes[0, 0], axes[0, 1], axes[0, 2], axes[1, 0], axes[1, 1], axes[1, 2],
            axes[2, 0], axes[2, 1], axes[2, 2])


@numba.njit(**_INLINE)
def _apply9(m, x, y, z):
    """The matrix ``m`` (a 9-tuple from :func:`_rows`) applied to (x, y, z): the same
    products and sums, in the same order, as on the array."""
    return (m[0] * x + m[1] * y + m[2] * z, m[3] * x + m[4] * y + m[5] * z,
            m[6] * x + m[7] * y + m[8] * z)


@numba.njit(**_INLINE)
def _dot(ax, ay, az, bx, by, bz):
    return ax * bx + ay * by + az * bz


@numba.njit(**_INLINE)
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


#: Taylor coefficients of sin (x^3 .. x^15), cos (x^2 .. x^16): on [0, pi/4] to 5e-17.
_SIN = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(1, 8))
_COS = tuple((-1.0) ** k / math.factorial(2 * k) for k in range(1, 9))


@numba.njit(**_ALWAYS)
def _turn(u):
    """cos and sin of 2 pi ``u``, ``u`` in [0, 1), within 1e-15 by polynomials after an
    exact reduction: faster than libm's cos, and the same bits on every machine."""
    q = 4.0 * u
    k = int(q)
    r = q - k  # exact
    flip = r > 0.5
    x = (1.0 - r if flip else r) * (0.5 * math.pi)  # in [0, pi/4]
    # the polynomials in x^2 by Estrin's scheme: pairs, then pairs of pairs, so the
    # multiplications run side by side (a chain of 4 steps, not Horner's 8)
    x2 = x * x
    x4 = x2 * x2
    x8 = x4 * x4
    s = x + x * x2 * ((_SIN[0] + x2 * _SIN[1]) + x4 * (_SIN[2] + x2 * _SIN[3])
                      + x8 * ((_SIN[4] + x2 * _SIN[5]) + x4 * _SIN[6]))
    c = 1.0 + x2 * ((_COS[0] + x2 * _COS[1]) + x4 * (_COS[2] + x2 * _COS[3])
                    + x8 * ((_COS[4] + x2 * _COS[5]) + x4 * (_COS[6] + x2 * _COS[7])))
    # the quadrant by selects and exact sign flips, no branches, so a loop that draws
    # directions runs on several photons at once: k = 0: (c, s), 1: (-s, c), 2: (-c, -s),
    # 3: (s, -c), the octant's swap first
    swap = ((k & 1) == 1) != flip
    a, b = (s, c) if swap else (c, s)
    return (-a if (k == 1) | (k == 2) else a), (-b if k >= 2 else b)


@numba.njit(**_INLINE)
def _basis(nx, ny, nz):
    """Two unit tangents completing unit ``n`` to a right-handed frame (Duff et al. 2017)."""
    sign = math.copysign(1.0, nz)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx), (b, sign + ny * ny * a, -ny)


@numba.njit(**_INLINE)
def _to_world(lx, ly, lz, nx, ny, nz):
    """Local (z along unit ``n``) to world."""
    t, b = _basis(nx, ny, nz)
    return (lx * t[0] + ly * b[0] + lz * nx, lx * t[1] + ly * b[1] + lz * ny,
            lx * t[2] + ly * b[2] + lz * nz)


@numba.njit(**_ALWAYS)
def _cosine_local(u1, u2):
    """A cosine-weighted direction about +z (pdf cos / pi per sr)."""
    st = math.sqrt(u1)
    c, s = _turn(u2)
    return st * c, st * s, math.sqrt(max(0.0, 1.0 - u1))


@numba.njit(**_ALWAYS)
def _cosine_about(nx, ny, nz, u1, u2):
    """A cosine-weighted direction about unit ``n`` (pdf cos / pi per sr)."""
    lx, ly, lz = _cosine_local(u1, u2)
    return _to_world(lx, ly, lz, nx, ny, nz)


@numba.njit(**_INLINE)
def _reflect(dx, dy, dz, nx, ny, nz):
    k = 2.0 * _dot(dx, dy, dz, nx, ny, nz)
    return dx - k * nx, dy - k * ny, dz - k * nz
