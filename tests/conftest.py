"""Shared fixtures: ``tests/helpers`` and the stress cases of ``tools/`` on sys.path, a
cache folder of the session's own, and OpenEXR's own ImfEnvmap as an oracle."""
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tools"))  # the stress case library
INSTALL_HINT = "apt-get install -y libopenexr-dev pkg-config g++"


def pytest_configure(config):
    """What the tests' runs keep (scenes, tables, compiled methods) goes to a folder of
    the session's own, removed at its end, not to the user's cache folder; the workers
    and every subprocess inherit it. A folder given in ``LUMITRACE_CACHE_DIR`` is used
    as it is."""
    if hasattr(config, "workerinput") or os.environ.get("LUMITRACE_CACHE_DIR"):
        return
    folder = tempfile.mkdtemp(prefix="lumitrace-tests-")  # this user's alone (0700)
    os.environ["LUMITRACE_CACHE_DIR"] = config.lumitrace_cache = folder


def pytest_unconfigure(config):
    folder = getattr(config, "lumitrace_cache", None)
    if folder:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="session")
def imf_probe(tmp_path_factory):
    """Compile tests/imf_envmap_probe.cpp against the system OpenEXR; return a runner."""
    if os.environ.get("LUMITRACE_SKIP_NATIVE") == "1":
        pytest.skip("LUMITRACE_SKIP_NATIVE=1: OpenEXR C++ oracle tests skipped")
    missing = [tool for tool in ("g++", "pkg-config") if shutil.which(tool) is None]
    if missing:
        pytest.fail(f"{', '.join(missing)} not found: the ImfEnvmap oracle test needs "
                    f"`{INSTALL_HINT}` (or set LUMITRACE_SKIP_NATIVE=1 to skip it)")
    flags = subprocess.run(["pkg-config", "--cflags", "--libs", "OpenEXR"],
                           capture_output=True, text=True)
    if flags.returncode != 0:
        pytest.fail("pkg-config finds no OpenEXR development files: run "
                    f"`{INSTALL_HINT}` (or set LUMITRACE_SKIP_NATIVE=1 to skip): "
                    + flags.stderr.strip())
    exe = tmp_path_factory.mktemp("imf_probe") / "imf_envmap_probe"
    build = subprocess.run(["g++", "-O1", "-std=c++14", "-o", str(exe),
                            str(HERE / "imf_envmap_probe.cpp"), *flags.stdout.split()],
                           capture_output=True, text=True)
    if build.returncode != 0:
        pytest.fail("cannot compile the ImfEnvmap probe (are the OpenEXR headers installed? "
                    f"`{INSTALL_HINT}`, or set LUMITRACE_SKIP_NATIVE=1 to skip):\n"
                    + build.stderr[-2000:])

    def run(lines: list[str]) -> np.ndarray:
        out = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True,
                             text=True, check=True)
        return np.array([[float(v) for v in line.split()] for line in out.stdout.splitlines()])

    return run


