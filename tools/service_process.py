"""A real ``lumitrace serve`` process on a free loopback port, for tests and tools."""
from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from lumitrace.client import Client


class Service:
    """Start ``lumitrace serve STAGE --port 0 ARGS`` and read its URL from its first line."""

    def __init__(self, stage: Path, *args, token: str | None = None, start_timeout=60.0):
        self.stage = Path(stage)
        cmd = [sys.executable, "-m", "lumitrace.cli", "serve", str(stage), "--port", "0",
               *map(str, args)]
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        env.pop("LUMITRACE_TOKEN", None)
        if token:  # as a user should: never on the command line, where ps shows it
            env["LUMITRACE_TOKEN"] = token
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env)
        self.lines: queue.Queue[str] = queue.Queue()
        self.stderr: list[str] = []
        threading.Thread(target=self._pump, args=(self.proc.stdout, self.lines.put),
                         daemon=True).start()
        threading.Thread(target=self._pump, args=(self.proc.stderr, self.stderr.append),
                         daemon=True).start()
        try:
            first = self.lines.get(timeout=start_timeout)
        except queue.Empty:
            self.kill()
            raise RuntimeError("the service did not start: " + "".join(self.stderr)) from None
        if " at http://" not in first:
            self.kill()
            raise RuntimeError(f"unexpected first line {first!r}: " + "".join(self.stderr))
        self.url = first.split(" at ", 1)[1].split()[0]
        self.client = Client(self.url, token=token)

    @staticmethod
    def _pump(stream, put) -> None:
        for line in stream:
            put(line)

    def wait_status(self, predicate, timeout: float = 120.0, step: float = 0.05) -> dict:
        """Poll /status until ``predicate(status)``; return it."""
        deadline = time.monotonic() + timeout
        while True:
            status = self.client.status()
            if predicate(status):
                return status
            if time.monotonic() > deadline:
                raise TimeoutError(f"status never matched: {status}")
            time.sleep(step)

    def wait_event(self, predicate, timeout: float = 30.0):
        """The first event the service keeps that matches ``predicate``."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = [e for e in self.client.history(0) if predicate(e)]
            if found:
                return found[0]
            time.sleep(0.1)
        raise TimeoutError("no such event")

    def wait_done(self, revision: int, pictures: bool = True, timeout: float = 120.0) -> dict:
        """Wait until ``revision`` is traced to its end and written."""
        return self.wait_status(lambda s: s["traced_revision"] == revision
                                and s["state"] == "done" and s["written_revision"] == revision
                                and s["written_photons"] == s["photons"]
                                and (s["written_pictures"] or not pictures), timeout)

    def stop(self, sig=signal.SIGTERM, timeout: float = 120.0) -> tuple[int, str]:
        """Send ``sig`` and wait for the exit; return (status, the rest of stdout)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        rc = self.proc.wait(timeout)
        time.sleep(0.05)
        rest = []
        while not self.lines.empty():
            rest.append(self.lines.get())
        return rc, "".join(rest)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(30)

    def __enter__(self) -> "Service":
        return self

    def __exit__(self, *exc) -> None:
        self.kill()
