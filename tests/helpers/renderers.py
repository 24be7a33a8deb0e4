"""The photometric solid's renderer processes running on this machine, found in /proc."""
from __future__ import annotations

import os


def renderers(parent: int | None = None) -> set[int]:
    """Pids of the running renderer processes (by their command line, or a forked one's
    name; an ended one not yet collected is not running), of ``parent``'s only when given
    (other tests running beside one start renderers of their own)."""
    out = set()
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/cmdline", "rb") as f, open(f"/proc/{d}/comm") as c:
                    if b"_lumitrace_solid_render" not in f.read() and \
                            c.read().strip() != "lumitrace-solid":
                        continue
                with open(f"/proc/{d}/stat") as f:
                    state, ppid = f.read().rsplit(")", 1)[1].split()[:2]
                if state != "Z" and (parent is None or int(ppid) == parent):
                    out.add(int(d))
            except (OSError, ValueError, IndexError):
                pass
    return out
