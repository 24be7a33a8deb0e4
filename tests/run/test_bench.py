"""``lumitrace bench`` as a user runs it: its figures are consistent with one another and it
says which kernels it measured (worker processes load the same build as the CLI)."""
import json
import subprocess
import sys

import pytest

from lumitrace.trace import compiled


@pytest.mark.parametrize("workers", ["threads", "processes"])
def test_bench_reports_consistent_figures_and_its_kernels(workers):
    out = subprocess.run([sys.executable, "-m", "lumitrace.cli", "bench", "--seconds", "0.3",
                          "--threads", "2", "--workers", workers, "--json"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert r["kernels"] == compiled.backend() and r["workers"] == workers
    assert r["segments"] >= r["photons"] > 0 and r["triangles"] > 0
    assert r["photons_per_second"] == pytest.approx(r["photons"] / r["trace_seconds"])
    assert r["raw_rays_per_second"] == pytest.approx(r["segments"] / r["raw_seconds"])
    assert r["ratio"] == pytest.approx(r["raw_seconds"] / r["trace_seconds"])
    assert 0.0 < r["ratio"] < 2.0  # Embree's share of the tracer's time, not a timing bound
