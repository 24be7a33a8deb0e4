"""Running a documentation page's examples as written: the conventions a page uses to say
how a block runs are in docs/explanation/architecture.md."""
from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from helpers.paths import ROOT

DOCS = ROOT / "docs"
#: Every page whose examples run: the site's pages and the README.
PAGES = sorted(DOCS.rglob("*.md")) + [ROOT / "README.md"]
#: The pages of the five-minute tour (run beside the others, in a test module of their own).
TOUR = [ROOT / "README.md", DOCS / "getting-started.md"]
#: The port the examples name; a page's service listens on a free one instead.
EXAMPLE_PORT = "8650"
#: Seconds one block may take (a few photons each: most take one or two).
BLOCK_TIMEOUT = 300


@dataclass
class Block:
    lang: str
    text: str
    line: int
    directive: str = ""  # what the comment before the block says (see the module's doc)


def blocks(page: Path) -> list[Block]:
    """The fenced code blocks of a page, each with the ``<!-- test: ... -->`` comment on
    the line before its fence, if any."""
    out, lines = [], page.read_text().splitlines()
    i = 0
    while i < len(lines):
        fence = re.match(r"^(```+)\s*([\w-]*)", lines[i])
        if fence:
            start, ticks = i, fence.group(1)
            i += 1
            while i < len(lines) and not lines[i].startswith(ticks):
                i += 1
            previous = lines[start - 1].strip() if start else ""
            said = re.fullmatch(r"<!-- test: (.*) -->", previous)
            out.append(Block(fence.group(2), "\n".join(lines[start + 1:i]) + "\n",
                             start + 1, said.group(1) if said else ""))
        i += 1
    return out


def _env() -> dict[str, str]:
    """The environment the examples run in: this interpreter's ``lumitrace`` and
    ``python`` first on the path, as after activating its venv."""
    bin_dir = str(Path(sys.executable).parent)
    return {**os.environ, "PATH": bin_dir + os.pathsep + os.environ.get("PATH", ""),
            "PYTHONUNBUFFERED": "1", "COLUMNS": "100"}


class PageService:
    """A ``lumitrace serve`` a page starts (or one started for a block), on a free port."""

    def __init__(self, argv: list[str], cwd: Path):
        self.proc = subprocess.Popen([*argv, "--port", "0"], cwd=cwd, env=_env(), text=True,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     start_new_session=True)
        first = self.proc.stdout.readline()
        if " at http://" not in first:
            self.proc.kill()
            raise AssertionError(f"{shlex.join(argv)} did not start: {first}"
                                 f"{self.proc.stderr.read()}")
        self.url = first.split(" at ", 1)[1].split()[0].rstrip("/")
        self.port = self.url.rsplit(":", 1)[1]

    def stop(self) -> None:
        """SIGTERM: the service writes its last result and exits 0."""
        self.proc.send_signal(signal.SIGTERM)
        try:
            out, err = self.proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            raise AssertionError("the service did not stop within 120 s") from None
        assert self.proc.returncode == 0, err[-3000:]


#: What a ``blender`` Python block runs after: the add-on registered in an empty scene, as
#: in Blender with the add-on installed and a new empty file.
BLENDER_PRELUDE = ("import bpy, lumitrace_blender\n"
                   "bpy.ops.wm.read_factory_settings(use_empty=True)\n"
                   "lumitrace_blender.register()\n")


def blender_python() -> Path | None:
    """The bpy environment's interpreter (``LUMITRACE_BLENDER_PYTHON``, else the
    checkout's ``.venv-blender``), None where there is none."""
    given = os.environ.get("LUMITRACE_BLENDER_PYTHON")
    python = Path(given) if given else ROOT / ".venv-blender" / "bin" / "python"
    return python if python.exists() else None


def _run(block: Block, page: Path, cwd: Path, port: str | None) -> None:
    text = block.text if port is None else block.text.replace(EXAMPLE_PORT, port)
    where = f"{page.relative_to(ROOT)}:{block.line}"
    env = _env()
    if block.lang == "sh":
        argv = ["bash", "-e", "-o", "pipefail", "-c", text]
    elif block.directive == "blender":
        argv = [str(blender_python()), "-c", BLENDER_PRELUDE + text]
        env["PYTHONPATH"] = str(ROOT / "service")
    else:
        argv = [sys.executable, "-c", text]
    expected = int(block.directive.split()[1]) if block.directive.startswith("expect-exit") \
        else 0
    p = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True,
                       timeout=BLOCK_TIMEOUT)
    assert p.returncode == expected, \
        f"{where} exited {p.returncode}, not {expected}:\n{text}\n{p.stdout[-2000:]}" \
        f"\n{p.stderr[-4000:]}"


def run_page(page: Path, work: Path) -> int:
    """Run every example of ``page`` in ``work``, in order; the number run."""
    service: PageService | None = None
    ran = 0
    try:
        for block in blocks(page):
            said = block.directive
            if said.startswith("skip"):
                assert re.fullmatch(r"skip \(.+\)", said), f"{page}:{block.line}: a skip " \
                                                           "says why, in brackets"
                continue
            if said.startswith("file "):
                (work / said.split(None, 1)[1]).write_text(block.text)
                ran += 1
                continue
            if said == "blender" and blender_python() is None:
                continue  # Blender's Python is not installed here: the Blender tests say so
            if said == "stop-service":
                assert service is not None, f"{page}:{block.line}: no service to stop"
                service.stop()
                service = None
            if said == "service":
                assert service is None and block.lang == "sh", f"{page}:{block.line}"
                service = PageService(shlex.split(block.text.strip()), work)
                ran += 1
                continue
            if block.lang == "usda":
                from pxr import Sdf

                layer = Sdf.Layer.CreateAnonymous(".usda")
                assert layer.ImportFromString(block.text), f"{page}:{block.line}"
                ran += 1
            elif block.lang == "json":
                body = json.loads(block.text)
                if "deltas" in body and service is not None:
                    from lumitrace.client import Client

                    Client(service.url).send(body["deltas"])
                ran += 1
            elif block.lang in ("sh", "python"):
                if said.startswith("service "):
                    stage = said.split(None, 1)[1]
                    own = PageService(["lumitrace", "serve", stage, "--photons", "100000",
                                       "--out", f"served-{block.line}", "--no-sublayer",
                                       "--quiet"], work)
                    try:
                        _run(block, page, work, own.port)
                    finally:
                        own.stop()
                else:
                    _run(block, page, work, service.port if service else None)
                ran += 1
        if service is not None:
            service.stop()
            service = None
    finally:
        if service is not None and service.proc.poll() is None:
            os.killpg(service.proc.pid, signal.SIGKILL)
    return ran


def work_folder(tmp_path: Path) -> Path:
    """A fresh copy of what the examples read: the stages and the schema."""
    work = tmp_path / "work"
    work.mkdir()
    shutil.copytree(ROOT / "schemas", work / "schemas")
    tracked = subprocess.run(["git", "ls-files", "stages"], cwd=ROOT, capture_output=True,
                             text=True).stdout.split()
    if tracked:  # the stages and their inputs as committed, not a trace's outputs beside them
        for name in tracked:
            (work / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, work / name)
    else:  # not a git checkout: everything but what a trace writes
        shutil.copytree(ROOT / "stages", work / "stages",
                        ignore=shutil.ignore_patterns("*.exr", "*.png", "*.lumitrace.usda",
                                                      "*.photometry.json", ".*"))
    return work
