"""Photon batches on a Dask cluster: the same seam as the thread and process pools.

The scene goes to every worker once (``scatter(broadcast=True)``); each worker prepares it
once per scene hash and frame and keeps it, so a batch ships only its small job record and
brings back its compacted tally. Tallies are handed back in job order, so a run on the
cluster adds exactly what a local run adds. A worker lost mid-batch costs nothing but time:
the scheduler runs its batches again elsewhere, and the run counts them (``redone``). The
scheduler soon keeps a single copy of scattered data: a worker lost with the scene's last
copy costs the scene sent again with the round's remaining batches. A scheduler that goes
away ends the run: the batches gathered until then are kept (:class:`ClusterLost`). Dask
is imported only here, only when a scheduler is named.
"""
from __future__ import annotations

import functools
import hashlib
import pickle
import threading
import uuid
import zlib
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from ..film.accumulate import SparseCounts
from ..errors import ClusterLost, LumitraceError
from ..film.tally import BatchTally
from ..scene import Scene
from ..trace.job import BatchJob

#: The parts of the package whose code decides a batch's tally: a worker whose copy of
#: them differs from the client's is refused (it could trace other photons).
TRACER_PARTS = ("scene", "trace", "film")
#: Seconds to wait for the scheduler and for at least one worker.
CONNECT_SECONDS = 30.0
#: Seconds between looks at whether a round that may be interrupted still matters.
POLL_SECONDS = 0.02
#: Times a round sends the scene again after the cluster lost it, before it gives up.
MAX_RESENDS = 3

_prepared: dict = {}
_prepare_lock = threading.Lock()


def identity() -> tuple[str, str]:
    """(lumitrace version, hash of the tracer's code) of this process: what a worker must
    share with the client to trace the same photons."""
    from .. import __version__

    return __version__, _code_hash()


@functools.lru_cache(maxsize=1)
def _code_hash() -> str:
    """A hash of the tracer's sources as this process loaded them (read once: every batch
    checks it)."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for part in TRACER_PARTS:
        for path in sorted((root / part).rglob("*.py")):  # trace/kernels/ included
            h.update(path.relative_to(root).as_posix().encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:12]


class _SceneLost(Exception):
    """The cluster cancelled a batch while the scheduler is still there (the scene's last
    copy went with a worker)."""


class WorkerMismatch(RuntimeError):
    """Raised on a worker whose lumitrace is not the client's (one that joined late)."""


def _narrow(a: np.ndarray) -> tuple:
    """An int64 array in the narrowest unsigned type that holds it exactly, and its type."""
    if a.dtype == np.int64 and a.size and a.min() >= 0:
        top = a.max()
        for t in (np.uint8, np.uint16, np.uint32):
            if top <= np.iinfo(t).max:
                return a.astype(t), a.dtype.str
    return a, a.dtype.str


def _encode(v):
    if isinstance(v, SparseCounts):  # sorted texel indices: their steps are small
        return ("s", v.ntex, _narrow(np.diff(v.idx, prepend=0)), _narrow(v.val))
    if isinstance(v, np.ndarray):
        return ("d", _narrow(v))
    if isinstance(v, tuple):
        return ("t", tuple(_encode(x) for x in v))
    return ("v", v)


def _decode(v):
    kind = v[0]
    if kind == "s":
        (steps, _), (val, dt) = v[2], v[3]
        return SparseCounts(v[1], np.cumsum(steps, dtype=np.int64), val.astype(dt))
    if kind == "d":
        return v[1][0].astype(v[1][1])
    if kind == "t":
        return tuple(_decode(x) for x in v[1])
    return v[1]


def pack(tally: BatchTally) -> bytes:
    """A compacted tally as sent over the network: its int64 counts in the narrowest
    exact type, deflated (the demo's batch of 131,072 photons: 1.7 MB pickled, 72 kB)."""
    state = {k: _encode(v) for k, v in vars(tally).items()}
    return zlib.compress(pickle.dumps(state, protocol=5), 1)


def unpack(data: bytes) -> BatchTally:
    """The tally :func:`pack` sent, bit for bit."""
    return BatchTally(**{k: _decode(v) for k, v in pickle.loads(zlib.decompress(data)).items()})


def _run_batch(expected: tuple[str, str], key: str, scene_and_frame, job: BatchJob,
               records: bool = False) -> bytes:
    """Trace one job on a worker (with its photons' records where asked), the scene
    prepared once per worker (``key``: the scene's hash and frame) and kept for the batches
    that follow."""
    mine = identity()
    if mine != expected:
        from distributed import get_worker

        raise WorkerMismatch(f"({get_worker().address}) runs lumitrace {mine[0]} (tracer "
                             f"{mine[1]}), the client {expected[0]} (tracer {expected[1]})")
    ps = _prepared.get(key)
    if ps is None:
        from ..trace.prepared import prepare

        with _prepare_lock:
            ps = _prepared.get(key)
            if ps is None:
                scene, frame = scene_and_frame
                ps = prepare(scene, frame)
                _prepared.clear()  # one scene at a time: a sweep's next stage replaces it
                _prepared[key] = ps
    from ..film.accumulate import compact
    from ..trace.tracer import trace_batch

    tally = trace_batch(ps, job, records=records)  # compacted as the local pools do
    tally.counts, tally.cells = compact(tally.counts), compact(tally.cells)
    return pack(tally)


def _story_processing(dask_scheduler, keys: list) -> int:
    """Times beyond the first that the scheduler sent these tasks to a worker (batches run
    again after a worker was lost)."""
    runs: dict = {}
    for entry in dask_scheduler.story(*keys):
        if entry[2] == "processing":
            runs[entry[0]] = runs.get(entry[0], 0) + 1
    return sum(max(0, n - 1) for n in runs.values())


def connect(address: str, timeout: float = CONNECT_SECONDS):
    """A Dask client on the scheduler at ``address``, with every worker checked to run
    this lumitrace; a clear error when there is no scheduler, no worker or a mismatch."""
    try:
        from distributed import Client
    except ImportError:
        raise LumitraceError("--scheduler needs Dask: pip install 'lumitrace[dask]'",
                             address) from None
    _quiet_client_log()
    try:
        client = Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise LumitraceError(f"cannot reach the Dask scheduler: {exc}", address) from None
    try:
        client.wait_for_workers(1, timeout=timeout)
        check_workers(client)
    except BaseException as exc:
        client.close()
        if isinstance(exc, TimeoutError):
            raise LumitraceError(f"no Dask worker joined the scheduler in {timeout:g} s",
                                 address) from None
        raise
    return client


def _quiet_client_log() -> None:
    """The client's own log of a lost scheduler (tracebacks of every reconnection try) is
    not shown: the run ends with one line saying so (:class:`ClusterLost`)."""
    import logging

    logging.getLogger("distributed.client").setLevel(logging.CRITICAL)


def check_workers(client) -> None:
    """Refuse a cluster where any worker runs another lumitrace or tracer code."""
    mine = identity()
    try:
        theirs = client.run(identity)
    except ModuleNotFoundError:
        raise LumitraceError("a Dask worker cannot import lumitrace: install the same "
                             "lumitrace on every worker", client.scheduler.address) from None
    bad = {w: v for w, v in theirs.items() if tuple(v) != mine}
    if bad:
        w, v = sorted(bad.items())[0]
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise LumitraceError(
            f"Dask worker {w}{more} runs lumitrace {v[0]} (tracer {v[1]}), this run "
            f"{mine[0]} (tracer {mine[1]}): install the same lumitrace on every worker",
            client.scheduler.address)


def total_threads(client) -> int:
    """Threads of all the cluster's workers now."""
    workers = client.scheduler_info(n_workers=-1)["workers"]
    return max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()))


class ClusterRunner:
    """Maps jobs to their tallies, in job order, on the cluster's workers: the callable a
    session traces its rounds with. ``threads``: the cluster's threads (a round's size);
    ``redone``: batches run again after a worker was lost; ``batches``: batches traced."""

    def __init__(self, client, scene: Scene | None = None, frame=None):
        self.client = client
        self.address = client.scheduler.address
        self.expected = identity()
        self.key: str | None = None
        self.scene = None  # the scattered (scene, frame)
        self._payload = None
        self.threads = total_threads(client)
        self.redone = 0
        self.batches = 0
        self._run = uuid.uuid4().hex[:12]
        if scene is not None:
            self.use(scene, frame)

    def use(self, scene: Scene, frame) -> None:
        """Trace ``scene`` in ``frame`` from now on: sent to every worker once, and again
        only when it changed (a service's next revision)."""
        key = f"{scene.content_hash()}-{frame!r}"
        if key != self.key:
            self._payload = (scene, frame)
            self._send_scene()
            self.key = key

    def _send_scene(self) -> None:
        self.scene = self.client.scatter(self._payload, broadcast=True, hash=False)

    def _submit(self, jobs: list[BatchJob], records: bool) -> tuple[list, list]:
        keys = [f"lumitrace-batch-{self._run}-{self.batches + i}" for i in range(len(jobs))]
        self.batches += len(jobs)
        return keys, [self.client.submit(_run_batch, self.expected, self.key, self.scene, job,
                                         records, key=k, pure=False)
                      for job, k in zip(jobs, keys)]

    def __call__(self, jobs: Iterable[BatchJob], records: bool = False,
                 interrupted: Callable[[], bool] | None = None) -> Iterator[BatchTally] | None:
        """The jobs' tallies in job order (with per-photon records where asked); None, the
        round's batches cancelled, as soon as ``interrupted()`` says so."""
        jobs = list(jobs)
        keys, futures = self._submit(jobs, records)
        got: list[BatchTally] = []
        resent = 0
        try:
            while len(got) < len(jobs):
                i = len(got)
                try:
                    tally = self._result(futures[i], interrupted)
                except _SceneLost as exc:
                    # every copy of the scene was on workers that went away (the scheduler
                    # keeps one copy of scattered data): send it again, and the batches
                    # from here on
                    resent += 1
                    if resent > MAX_RESENDS:
                        raise LumitraceError(f"the cluster lost the scene {resent - 1} times "
                                             f"in one round ({exc})", self.address) from None
                    self.client.cancel(futures[i:])
                    self._send_scene()
                    keys[i:], futures[i:] = self._submit(jobs[i:], records)
                    self.redone += len(jobs) - i
                    continue
                if tally is None:
                    self.client.cancel(futures)
                    return None
                got.append(tally)
        except ClusterLost as lost:
            lost.tallies = got  # the batches that finished, a prefix of the round's jobs
            raise
        except BaseException:
            self.client.cancel(futures)
            raise
        self.redone += self._count_redone(keys)
        return iter(got)

    def _result(self, future, interrupted=None) -> BatchTally | None:
        from distributed import KilledWorker
        from distributed.client import FutureCancelledError

        try:
            if interrupted is not None:
                # a done-callback, not ``result(timeout=...)``: the latter's timeout races
                # the result in distributed's ``sync`` and can lose both
                done = threading.Event()
                future.add_done_callback(lambda _: done.set())
                while not done.wait(POLL_SECONDS):
                    if interrupted():
                        return None
                    if self.client.status not in ("running", "connecting"):
                        break  # the client is closing: ``result`` says how
            return unpack(future.result())
        except KilledWorker as exc:
            raise LumitraceError(f"a batch lost its worker too often ({exc}): the batch "
                                 "itself may crash workers", self.address) from None
        except WorkerMismatch as exc:
            raise LumitraceError(f"a Dask worker that joined during the run {exc}: install "
                                 "the same lumitrace on every worker", self.address) from None
        except FutureCancelledError as exc:
            if exc.reason != "scheduler-connection-lost" and self.client.status == "running":
                raise _SceneLost(exc.reason) from None
            raise ClusterLost("the Dask scheduler went away mid-run", self.address,
                              []) from None
        except (OSError, TimeoutError):
            if self.client.status in ("running", "connecting"):
                raise
            raise ClusterLost("the Dask scheduler went away mid-run", self.address,
                              []) from None

    def _count_redone(self, keys: list) -> int:
        try:
            return int(self.client.run_on_scheduler(_story_processing, keys=keys))
        except Exception:  # noqa: BLE001 - a count for the record, never a failure
            return 0

    def close(self) -> None:
        """Leave the cluster (its workers stay for the next run)."""
        import contextlib

        with contextlib.suppress(Exception):
            self.client.close(timeout=5)


def cluster_runner(address: str, scene: Scene, frame):
    """A :class:`ClusterRunner` on the scheduler at ``address`` and its client."""
    client = connect(address)
    try:
        return ClusterRunner(client, scene, frame)
    except BaseException:
        client.close()
        raise
