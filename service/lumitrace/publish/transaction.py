"""The outputs of one run as one transaction: they appear together or not at all.

A run writes every file into a staging folder beside its target (same file system, so a
rename is atomic), flushes them to disk, then commits: a journal naming every
(staged, target) pair is written and flushed, which is the commit point; the staged files
are renamed onto their targets, the result layer last, and the journal is removed. Signals
are held during the commit, so SIGINT, SIGTERM or SIGHUP at any moment leave either the
earlier complete set or the new complete set. A crash (SIGKILL, power loss) after the
commit point leaves the journal: the next run (or service start) rolls it forward before
it does anything else, and removes staging folders of runs that never committed.

The journal is trusted only as far as lumitrace wrote it: it is signed with a key only
the user running lumitrace can read (:func:`journal_key`), and even a signed journal may
only rename a file out of this stage's staging folder onto one of the stage's output names
in the same folder (:func:`_checked_moves`). A journal that fails either test is ignored,
with a warning, and nothing it names is touched.

One run at a time publishes a stage's outputs: a lock file beside each target folder,
taken in a fixed order, makes a second run wait (up to ``wait`` seconds, then a clear
error). The lock file is removed when the run releases it, so none outlives its run (one
left by a killed run is taken over: the kernel released its lock). Each file carries the
run id (EXR header, IES keyword, LDT report line, result layer metadata), so a reader can
tell that files belong together.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import glob
import hashlib
import hmac
import json
import os
import re
import stat
import tempfile
import shutil
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from ..atomic import fsync_path
from ..errors import OutputError
from ..filenames import output_names

#: Signals held while the staged files are renamed into place.
HELD_SIGNALS = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}
#: Seconds a run waits for another run of the same stage to finish publishing.
DEFAULT_LOCK_WAIT = 120.0
_STAGING = ".lumitrace-staging-"
_JOURNAL = ".lumitrace-journal"
_LOCK = ".lumitrace.lock"


def new_run_id() -> str:
    """A short unique id for one run's set of files: 64 random bits in 16 hex digits (not
    uuid's, whose loading costs every command 2 ms)."""
    return os.urandom(8).hex()


def _lock_path(folder: Path, name: str) -> Path:
    return folder / f".{name}{_LOCK}"


def journal_path(folder: Path, name: str) -> Path:
    """Where the publishing journal of stage ``name``'s outputs in ``folder`` is, while a
    commit is under way (or was cut short)."""
    return _journal_path(folder, name)


def journal_is_ours(path: Path) -> bool:
    """Whether the journal at ``path`` is one this user's lumitrace signed (one that
    :func:`recover` would finish)."""
    try:
        record = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(record, dict) and _signed_by_us(record)


def _journal_path(folder: Path, name: str) -> Path:
    return folder / f".{name}{_JOURNAL}"


def _open_lock(path: Path) -> int:
    """An open descriptor of the lock file (created if missing); read-only where another
    user's lock file, left by a killed run, cannot be opened for writing (flock needs no
    write access)."""
    try:
        return os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o666)
    except PermissionError:
        try:
            return os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
        except OSError as exc:
            raise OutputError(f"cannot open the lock file: {exc.strerror}", str(path)) \
                from exc
    except OSError as exc:
        raise OutputError(f"cannot create the lock file: {exc.strerror}", str(path)) from exc


def _take_lock(path: Path, name: str, wait: float) -> int:
    """Hold the flock of ``path`` (the file as it is named now, not an unlinked one that
    the previous holder removed while we waited); returns its descriptor."""
    deadline = time.monotonic() + wait
    while True:
        fd = _open_lock(path)
        try:
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
            try:
                same = os.stat(path, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                with contextlib.suppress(OSError):
                    os.ftruncate(fd, 0)
                    os.pwrite(fd, str(os.getpid()).encode(), 0)
                return fd
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)  # the holder removed it as we waited: lock the file named now


@contextlib.contextmanager
def locked(folders: list[Path], name: str, wait: float = DEFAULT_LOCK_WAIT) -> Iterator[None]:
    """Hold the publishing lock of stage ``name`` in every folder (sorted: no deadlock);
    the lock files are removed on release, so none outlives the run."""
    handles: list[tuple[Path, int]] = []
    try:
        for folder in sorted({f.resolve() for f in folders}):
            path = _lock_path(folder, name)
            handles.append((path, _take_lock(path, name, wait)))
        yield
    finally:
        for path, fd in reversed(handles):
            with contextlib.suppress(OSError):
                os.unlink(path)  # still held: a waiter finds it gone and locks anew
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
    removals: list[Path] = field(default_factory=list)  # earlier outputs the run drops
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
        strays = [str(t) for t in self.targets if t.parent != Path(self.home).absolute()]
        if strays:
            raise OutputError("a run publishes into its result layer's folder only: "
                              + ", ".join(strays))
        last = Path(last).absolute() if last is not None else None
        order = sorted(self.targets, key=lambda t: (t == last, str(t)))
        journal = _journal_path(self.home, self.name)
        record = sign({"run": self.run_id, "name": self.name,
                       "moves": [[str(self.targets[t]), str(t)] for t in order],
                       "removals": [str(Path(r).absolute()) for r in self.removals]})
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


def _key_file() -> Path:
    base = os.environ.get("XDG_STATE_HOME") or os.path.join(os.path.expanduser("~"),
                                                            ".local", "state")
    return Path(base) / "lumitrace" / "journal.key"


def _read_or_make_key(path: Path) -> bytes:
    """The 32-byte key in ``path``, made (mode 0600) if missing; refused unless it is this
    user's own file that nobody else can read."""
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    except FileExistsError:
        pass
    else:
        with os.fdopen(fd, "wb") as fh:
            fh.write(os.urandom(32))
            fh.flush()
            os.fsync(fh.fileno())
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    with os.fdopen(fd, "rb") as fh:
        st = os.fstat(fh.fileno())
        key = fh.read()
    if st.st_uid != os.geteuid() or st.st_mode & 0o077 or len(key) != 32:
        raise PermissionError(f"{path} is not this user's private key")
    return key


_KEY: list[bytes | None] = []


def journal_key() -> bytes | None:
    """This user's key for signing publishing journals: in the user's state folder
    (``$XDG_STATE_HOME/lumitrace``), or a private folder in the temporary folder where the
    home is not writable; None where neither can be had (journals then go unsigned and
    are never rolled forward)."""
    if not _KEY:
        fallback = Path(tempfile.gettempdir()) / f"lumitrace-{os.geteuid()}" / "journal.key"
        for place in (_key_file(), fallback):
            try:
                _KEY.append(_read_or_make_key(place))
                break
            except OSError:
                continue
        else:
            _KEY.append(None)
    return _KEY[0]


def _mac(record: dict, key: bytes) -> str:
    body = json.dumps({k: v for k, v in record.items() if k != "mac"}, sort_keys=True)
    return hmac.new(key, body.encode(), hashlib.sha256).hexdigest()


def sign(record: dict) -> dict:
    """``record`` with its signature (``mac``) by this user's :func:`journal_key`."""
    key = journal_key()
    return {**record, "mac": _mac(record, key)} if key is not None else dict(record)


def _signed_by_us(record: dict) -> bool:
    key = journal_key()
    mac = record.get("mac")
    return key is not None and isinstance(mac, str) and \
        hmac.compare_digest(mac, _mac(record, key))


_RUN_ID = re.compile(r"^[0-9a-f]{16}$")


def _is_plain(path: Path, kind: int) -> bool:
    """Whether ``path`` exists as a ``kind`` (stat.S_IFREG, S_IFDIR) and is no symlink."""
    try:
        return stat.S_IFMT(os.lstat(path).st_mode) == kind
    except OSError:
        return False


def _checked_moves(record: dict, folder: Path, name: str
                   ) -> tuple[list[tuple[Path, Path]], list[Path]]:
    """The renames and removals of a journal found in ``folder``, each checked to be one a
    run of stage ``name`` makes: from this stage's staging folder of the journal's run
    (a real folder, no symlink, beside its target) onto the same file name, one of the
    stage's output names, in ``folder``. Raises ValueError naming the first that is not."""
    run = record.get("run")
    if not isinstance(run, str) or not _RUN_ID.match(run) or record.get("name") != name:
        raise ValueError("not a journal of this stage")
    allowed = output_names(name)
    staging = folder / f".{name}{_STAGING}{run}"
    moves, removals = [], []
    for pair in record.get("moves", ()):
        if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(x, str)
                                                                  for x in pair)):
            raise ValueError(f"malformed move {pair!r}")
        staged, target = Path(pair[0]), Path(pair[1])
        if target.parent != folder or target.name not in allowed or \
                staged != staging / target.name:
            raise ValueError(f"a move lumitrace does not make: {pair[0]} -> {pair[1]}")
        moves.append((staged, target))
    for item in record.get("removals", ()):
        target = Path(item) if isinstance(item, str) else None
        if target is None or target.parent != folder or target.name not in allowed:
            raise ValueError(f"a removal lumitrace does not make: {item!r}")
        removals.append(target)
    if moves and not _is_plain(staging, stat.S_IFDIR):
        raise ValueError(f"the staging folder {staging} is not a plain folder")
    return moves, removals


def _roll_forward(journal: Path, record: dict) -> None:
    """Rename every staged file of a committed journal onto its target, remove the files
    the run dropped, then clean up."""
    moves, removals = _checked_moves(record, journal.parent, record.get("name"))
    for staged, target in moves:
        if _is_plain(staged, stat.S_IFREG):
            os.replace(staged, target)
    for target in removals:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(target)
    fsync_path(journal.parent)
    for staged, _ in moves[:1]:
        with contextlib.suppress(OSError):
            staged.parent.rmdir()
    journal.unlink(missing_ok=True)
    fsync_path(journal.parent)


def recover(folders: list[Path], name: str, file_names: list[str] = ()) -> list[str]:
    """Finish an interrupted commit of stage ``name`` (only a journal this user's
    lumitrace signed, and only the moves a run makes), remove staging folders of runs
    that never committed and temporary files of interrupted atomic writes of
    ``file_names``; call with the lock held. Returns what was done, for warnings."""
    done = []
    for folder in {f.absolute() for f in folders}:
        journal = _journal_path(folder, name)
        if journal.exists():
            try:
                record = json.loads(journal.read_text(encoding="utf-8"))
                if not isinstance(record, dict):
                    raise ValueError("not a JSON object")
            except (OSError, ValueError) as exc:
                raise OutputError(f"cannot read an interrupted publishing ({exc}); "
                                  "remove the journal to discard it", str(journal)) from exc
            if not _signed_by_us(record):
                done.append(f"{journal}: ignored a publishing journal this user's lumitrace "
                            "did not write (nothing it names was touched)")
            else:
                try:
                    _roll_forward(journal, record)
                except ValueError as exc:
                    done.append(f"{journal}: ignored a publishing journal naming files "
                                f"lumitrace does not write ({exc})")
                except OSError as exc:
                    raise OutputError(f"cannot complete an interrupted publishing ({exc}); "
                                      "remove the journal to discard it", str(journal)) \
                        from exc
                else:
                    done.append(f"completed the interrupted publishing of run "
                                f"{record['run']} in {folder}")
        with contextlib.suppress(OSError):
            (folder / f".{name}{_JOURNAL}.tmp").unlink()
        if not folder.is_dir():
            continue
        for stale in folder.glob(f".{glob.escape(name)}{_STAGING}*"):
            if _is_plain(stale, stat.S_IFDIR):
                shutil.rmtree(stale, ignore_errors=True)
                done.append(f"removed the unfinished outputs of an interrupted run "
                            f"({stale.name})")
        for file_name in file_names:
            stem, suffix = os.path.splitext(file_name)
            # atomic_path's temporary names: ".STEM.XXXXXXXX.tmpSUFFIX" (mkstemp: 8 chars)
            for tmp in folder.glob(f".{glob.escape(stem)}.????????.tmp{glob.escape(suffix)}"):
                with contextlib.suppress(OSError):
                    tmp.unlink()
                    done.append(f"removed the temporary file {tmp.name} of an interrupted run")
    return done
