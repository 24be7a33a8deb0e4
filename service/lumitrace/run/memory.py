"""Memory a session will need, estimated before it starts, and refused above what the
machine has: a run should fail at once with a reason, not be killed an hour in."""
from __future__ import annotations

import os

from ..errors import LumitraceError
from ..film import accumulate

#: float64 maps of the texel count alive at once while a map is estimated and written
#: (raw, filtered, halves, variances, the filter's pyramid, the EXR channels).
MAP_COPIES = 24


def estimate_bytes(emitters: int, resolution: int, threads: int,
                   photons: int | None) -> int:
    """Bytes of the accumulator, the batches in flight and the maps of one session."""
    ntex = 6 * resolution * resolution
    dense = emitters * 2 * ntex * 8
    if dense > accumulate.DENSE_COUNTS_BYTES:  # sparse: each photon at most one texel
        counts = min(dense, (photons or 10**8) * 3 * 8)
    else:
        counts = dense
    in_flight = 4 * max(1, threads) * 2 * ntex * 8
    return counts + in_flight + MAP_COPIES * ntex * 8


def available_bytes() -> int | None:
    """Memory available to a new allocation (Linux MemAvailable), or None if unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(emitters: int, resolution: int, threads: int, photons: int | None) -> int:
    """Raise a clear error when the session would need more memory than is available;
    return the estimate (bytes)."""
    need = estimate_bytes(emitters, resolution, threads, photons)
    have = available_bytes()
    if have is not None and need > 0.8 * have:
        raise LumitraceError(
            f"this run needs about {need / 2**30:.1f} GiB ({emitters:,} emitters, "
            f"resolution {resolution}, {threads} threads) and {have / 2**30:.1f} GiB is "
            "available: lower --resolution or --threads", "memory")
    return need
