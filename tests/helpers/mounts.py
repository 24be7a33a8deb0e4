"""Real file systems for tests: a size-limited tmpfs (full disks) and a read-only one."""
from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
from pathlib import Path
from typing import Callable, Iterator

import pytest


@contextlib.contextmanager
def tmpfs(mount: Path, size: str, fill: Callable[[Path], None] | None = None,
          read_only: bool = False) -> Iterator[Path]:
    """Mount a tmpfs of ``size`` at ``mount`` (made if missing), ``fill`` it, remount it
    read-only when asked; skipped with the reason where root or mount(8) is missing or
    mounting is not allowed."""
    mount.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("a real tmpfs needs root and mount(8)")
    p = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mount)],
                       capture_output=True, text=True)
    if p.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {p.stderr.strip()}")
    try:
        if fill is not None:
            fill(mount)
        if read_only:
            subprocess.run(["mount", "-o", "remount,ro", str(mount)], check=True)
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)
