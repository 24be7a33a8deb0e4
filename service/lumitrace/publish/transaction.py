"""The outputs of one run as one transaction: they appear together or not at all.

A run writes every file into a staging folder beside its target (same file system, so a
rename is atomic), flushes them to disk, then commits: a journal naming every
(staged, target) pair is written and flushed, which is the commit point; the staged files
are renamed onto their targets, the result layer last, and the journal is removed. Signals
are held during the commit, so SIGINT, SIGTERM or SIGHUP at any moment leave either the
earlier complete set or the new complete set. A crash (SIGKILL, power loss) after the
commit point leaves the journal: the next run (or service start) rolls it forward before
it does anything else, and removes staging folders of runs that never committed.

One run at a time publishes a stage's outputs: a lock file beside each target folder,
taken in a fixed order, makes a second run wait (up to ``wait`` seconds, then a clear
error). Each file carries the run id (EXR header, IES keyword, LDT report line, result
layer metadata), so a reader can tell that files belong together.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import glob
import json
import os
import shutil
import signal
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from ..atomic import fsync_path
from ..errors import OutputError

#: Signals held while the staged files are renamed into place.
HELD_SIGNALS = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}
#: Seconds a run waits for another run of the same stage to finish publishing.
DEFAULT_LOCK_WAIT = 120.0
_STAGING = ".lumitrace-staging-"
_JOURNAL = ".lumitrace-journal"
_LOCK = ".lumitrace.lock"


def new_run_id() -> str:
    """A short unique id for one run's set of files."""
    return uuid.uuid4().hex[:16]


def _lock_path(folder: Path, name: str) -> Path:
    return folder / f".{name}{_LOCK}"


def _journal_path(folder: Path, name: str) -> Path:
    return folder / f".{name}{_JOURNAL}"


@contextlib.contextmanager
def locked(folders: list[Path], name: str, wait: float = DEFAULT_LOCK_WAIT) -> Iterator[None]:
    """Hold the publishing lock of stage ``name`` in every folder (sorted: no deadlock)."""
    handles = []
    try:
        for folder in sorted({f.resolve() for f in folders}):
            path = _lock_path(folder, name)
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
            except OSError as exc:
                raise OutputError(f"cannot create the lock file: {exc.strerror}", str(path)) \
                    from exc
            handles.append(fd)
            deadline = time.monotonic() + wait
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except OSError as exc:
                    if exc.errno not in (errno.EAGAIN, errno.EACCES):
                        raise
                    if time.monotonic() >= deadline:
                        holder = os.pread(fd, 64, 0).decode(errors="replace").strip()
                        raise OutputError(
                            f"another lumitrace run (pid {holder or 'unknown'}) has been "
                            f"publishing results for '{name}' for over {wait:g} s",
                            str(path)) from None
                    time.sleep(0.05)
            os.ftruncate(fd, 0)
            os.pwrite(fd, str(os.getpid()).encode(), 0)
        yield
    finally:
        for fd in reversed(handles):
            os.close(fd)  # closing releases the lock


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP (delivered when the block ends); main thread only.

    The handlers are swapped for recorders rather than the signals masked: a signal mask
    holds only the calling thread, and the kernel hands a process's signal to any thread
    that does not block it (a library's worker thread), whose arrival Python then handles
    in the main thread, inside the block.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []
    old = {}
    for s in HELD_SIGNALS:
        prev = signal.getsignal(s)
        if prev is None:  # a handler not set from Python: leave it
            continue
        old[s] = prev
        signal.signal(s, lambda signum, _frame: got.append(signum))
    try:
        yield
    finally:
        for s, prev in old.items():
            signal.signal(s, prev)
        for s in dict.fromkeys(got):
            signal.raise_signal(s)


@dataclass
class Transaction:
    """The files of one run, staged beside their targets until :meth:`commit`.

    ``name`` is the stage's NAME (it names the lock, journal and staging folders); the
    journal lives in ``home``, the folder of the result layer.
    """

    name: str
    home: Path
    run_id: str = field(default_factory=new_run_id)
    targets: dict[Path, Path] = field(default_factory=dict)  # target -> staged file
    committed: bool = False
    folders: set[Path] = field(default_factory=set)  # staging folders, known before made

    def staged(self, target: str | os.PathLike) -> Path:
        """Where to write ``target``'s new content (the same folder's staging area)."""
        target = Path(target).absolute()
        folder = target.parent / f".{self.name}{_STAGING}{self.run_id}"
        self.folders.add(folder)
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"cannot write in the output folder: {exc.strerror}",
                              str(target.parent)) from exc
        path = folder / target.name
        self.targets[target] = path
        return path

    def _staging_folders(self) -> set[Path]:
        return set(self.folders)

    def abort(self) -> None:
        """Remove every staged file: the earlier outputs stay as they were."""
        for folder in self._staging_folders():
            shutil.rmtree(folder, ignore_errors=True)

    def commit(self, last: Path | None = None) -> None:
        """Publish every staged file at once (``last`` renamed after all the others)."""
        missing = [str(t) for t, s in self.targets.items() if not s.exists()]
        if missing:
            raise OutputError(f"staged output missing for {', '.join(missing)}")
        for staged in self.targets.values():
            fsync_path(staged)
        for folder in self._staging_folders():
            fsync_path(folder)
        last = Path(last).absolute() if last is not None else None
        order = sorted(self.targets, key=lambda t: (t == last, str(t)))
        journal = _journal_path(self.home, self.name)
        record = {"run": self.run_id,
                  "moves": [[str(self.targets[t]), str(t)] for t in order]}
        with signals_held():
            tmp = journal.with_name(journal.name + ".tmp")
            try:
                with open(tmp, "w", encoding="utf-8") as fh:
                    json.dump(record, fh)
                    fh.flush()
                    os.fsync(fh.fileno())
                os.replace(tmp, journal)
                fsync_path(self.home)
            except OSError as exc:
                with contextlib.suppress(OSError):
                    tmp.unlink()
                raise OutputError(f"cannot write the publishing journal: {exc.strerror}",
                                  str(journal)) from exc
            _roll_forward(journal, record)
            self.committed = True


def _roll_forward(journal: Path, record: dict) -> None:
    """Rename every staged file of a committed journal onto its target, then clean up."""
    folders = set()
    for staged, target in record["moves"]:
        staged, target = Path(staged), Path(target)
        if staged.exists():
            os.replace(staged, target)
        folders.add(target.parent)
        folders.add(staged.parent)
    for folder in folders:
        fsync_path(folder)
    for staged, _ in record["moves"]:
        with contextlib.suppress(OSError):
            Path(staged).parent.rmdir()
    journal.unlink(missing_ok=True)
    fsync_path(journal.parent)


def recover(folders: list[Path], name: str, file_names: list[str] = ()) -> list[str]:
    """Finish an interrupted commit of stage ``name``, remove staging folders of runs that
    never committed and temporary files of interrupted atomic writes of ``file_names``;
    call with the lock held. Returns what was done, for warnings."""
    done = []
    for folder in {f.absolute() for f in folders}:
        journal = _journal_path(folder, name)
        if journal.exists():
            try:
                record = json.loads(journal.read_text(encoding="utf-8"))
                _roll_forward(journal, record)
                done.append(f"completed the interrupted publishing of run {record['run']} "
                            f"in {folder}")
            except (OSError, ValueError, KeyError, TypeError) as exc:
                raise OutputError(f"cannot complete an interrupted publishing ({exc}); "
                                  "remove the journal to discard it", str(journal)) from exc
        with contextlib.suppress(OSError):
            (folder / f".{name}{_JOURNAL}.tmp").unlink()
        if not folder.is_dir():
            continue
        for stale in folder.glob(f".{name}{_STAGING}*"):
            shutil.rmtree(stale, ignore_errors=True)
            done.append(f"removed the unfinished outputs of an interrupted run ({stale.name})")
        for file_name in file_names:
            stem, suffix = os.path.splitext(file_name)
            # atomic_path's temporary names: ".STEM.XXXXXXXX.tmpSUFFIX" (mkstemp: 8 chars)
            for tmp in folder.glob(f".{glob.escape(stem)}.????????.tmp{glob.escape(suffix)}"):
                with contextlib.suppress(OSError):
                    tmp.unlink()
                    done.append(f"removed the temporary file {tmp.name} of an interrupted run")
    return done
