"""The README's first command, run as a user runs it on a clone: it traces the demo to its
target error and leaves the repository clean."""
from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from helpers.paths import ROOT


def _first_command() -> list[str]:
    """The lumitrace part of the README's first shell block (after the set-up)."""
    block = re.search(r"```sh\n(.*?)\n```", (ROOT / "README.md").read_text(), re.S).group(1)
    command = block.split("&&", 1)[1].strip()
    argv = shlex.split(command)
    assert argv[0] == ".venv/bin/lumitrace", argv
    return argv[1:]


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                    reason="needs git and a git checkout to clone")
def test_the_demo_command_reaches_its_target_and_leaves_the_clone_clean(tmp_path):
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True, timeout=120)
    argv = _first_command()
    run = subprocess.run([sys.executable, "-m", "lumitrace.cli", *argv, "--json",
                          "--no-progress"], cwd=clone, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    assert summary["converged"] and summary["target_reached"]
    assert Path(summary["outputs"]["ies"]).parent == clone / "results"
    assert Path(summary["outputs"]["result_layer"]).parent == clone / "results"
    status = subprocess.run(["git", "status", "--porcelain"], cwd=clone, capture_output=True,
                            text=True, check=True).stdout
    assert status == "", status
