"""Where the tasks of a run run: this process, a local Dask cluster or an existing one.

A long run (``predisat process``, ``predisat availability``) cuts its work into independent
tasks - chainage chunks, batches of frames, blocks of positions - each a call
``fn(shared, item)`` of one module-level task function. A :class:`TaskRunner` runs them where
its :class:`Scheduler` says:

* ``serial``: in this process, one after the other (or in ``workers`` threads);
* ``local``: a :class:`distributed.LocalCluster` of ``workers`` single-threaded worker
  processes, started on first use (a run with nothing to do starts none) and closed with the
  runner;
* an address (``tcp://host:8786``): the workers of an existing ``distributed`` cluster.

The same task function runs in every case, so the results do not depend on where they ran.
On a cluster a worker that dies (killed, out of memory) costs only the tasks it held: the
scheduler runs them again on another worker (``distributed.scheduler.allowed-failures`` times,
then the run fails with ``KilledWorker``). The local cluster's workers ignore Ctrl-C (SIGINT,
which a terminal sends to the whole process group): this process alone handles it, cancels
the queued tasks and closes the cluster within a few seconds (:data:`CLOSE_TIMEOUT_S`).
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import re
import signal
import socket
import threading
import uuid
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import Any, Literal, TypeVar

__all__ = [
    "CLOSE_TIMEOUT_S",
    "CONNECT_TIMEOUT_S",
    "WORKER_WAIT_S",
    "Scheduler",
    "TaskRunner",
    "dask_setup",
    "machine_workers",
]

S = TypeVar("S")
T = TypeVar("T")
R = TypeVar("R")

CLOSE_TIMEOUT_S = 3.0
"""Longest wait, seconds, for the client and for the local cluster to close."""

CONNECT_TIMEOUT_S = 20.0
"""Longest wait, seconds, for the scheduler of a cluster given by address to answer."""

_REFUSED_PROBE_S = 5.0  # a plain TCP connect first, to tell at once that nothing listens

WORKER_WAIT_S = 30.0
"""Longest wait, seconds, for a first worker to join a cluster given by address."""

# a worker process killed (SIGKILL, out of memory) while holding a task counts as a failure
# of that task; distributed gives up on a task after this many (its default is 3)
_ALLOWED_FAILURES = 5
# a worker process killed while the local cluster starts fails the start: it is tried again
_START_ATTEMPTS = 3


def machine_workers() -> int:
    """Cores this process may use (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


@dataclass(frozen=True)
class Scheduler:
    """Where a run's tasks run (see the module docstring).

    Attributes
    ----------
    kind : {"serial", "local", "address"}
    workers : int
        Threads (serial) or worker processes (local); 0 for a cluster given by address (its
        own workers).
    address : str
        The scheduler's address (``kind == "address"``), else ``""``.
    """

    kind: Literal["serial", "local", "address"]
    workers: int = 1
    address: str = ""

    @classmethod
    def serial(cls, threads: int = 1) -> Scheduler:
        """This process, with ``threads`` threads (1: one task after the other)."""
        if threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        return cls("serial", threads)

    @classmethod
    def local(cls, workers: int | None = None) -> Scheduler:
        """A local Dask cluster of ``workers`` processes (default: :func:`machine_workers`)."""
        n = machine_workers() if workers is None else workers
        if n < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        return cls("local", n)

    @classmethod
    def at(cls, address: str) -> Scheduler:
        """An existing ``distributed`` cluster: ``tcp://host:port`` or ``host:port``."""
        text = address.strip()
        port = text.rpartition(":")[2]
        if (
            not text or text.startswith("-") or any(c.isspace() for c in text)
            or ("://" not in text and not (":" in text and port.isdigit()))
        ):  # fmt: skip
            # a mistyped 'local' (lcoal) was taken for a host and failed after the inputs
            # were read and the output folder made
            raise ValueError(
                f"scheduler address {address!r} is not an address; give the Dask scheduler's "
                "address such as tcp://10.0.0.5:8786, or 'local' or 'serial'"
            )
        return cls("address", 0, text)

    @classmethod
    def parse(cls, text: str | None, workers: int | None = None) -> Scheduler:
        """The scheduler a command line or a library call names.

        Parameters
        ----------
        text : str or None
            ``"serial"``, ``"local"``, a scheduler address, or None: serial when ``workers``
            is None or 1, else a local cluster of ``workers`` processes.
        workers : int, optional
            Threads (serial) or worker processes (local); refused with an address (the
            cluster has its own).
        """
        if text is None:
            return cls.serial() if workers in (None, 1) else cls.local(workers)
        name = text.strip().lower()
        if name == "serial":
            return cls.serial(1 if workers is None else workers)
        if name == "local":
            return cls.local(workers)
        if workers is not None:
            raise ValueError(
                f"--workers {workers} with --scheduler {text}: an existing cluster has its own "
                "workers; leave --workers out (or use --scheduler local)"
            )
        return cls.at(text)

    def describe(self) -> str:
        """How progress messages name it: ``"serial"``, ``"local cluster of 2 workers"``..."""
        if self.kind == "serial":
            return "serial" if self.workers == 1 else f"serial, {self.workers} threads"
        if self.kind == "local":
            return f"local Dask cluster of {self.workers} worker(s)"
        return f"Dask cluster at {self.address}"


class _ReadyCluster:
    """A started client (and the local cluster it owns, if any)."""

    def __init__(
        self,
        scheduler: Scheduler,
        code_version: Callable[[], str] | None = None,
        paths: Sequence[str] = (),
    ) -> None:
        from distributed import Client

        self.cluster: Any = None
        if scheduler.kind == "local":
            self.cluster = _start_local_cluster(scheduler.workers)
            self.client = Client(self.cluster)
        else:
            self.client = _connect(scheduler.address)
            try:
                _check_workers(self.client, scheduler.address, code_version, paths)
            except BaseException:
                with contextlib.suppress(Exception):
                    self.client.close(timeout=CLOSE_TIMEOUT_S)
                raise

    def close(self, abort: bool = False) -> None:
        """Close the client and the local cluster; ``abort`` (after Ctrl-C or an error) kills
        the local worker processes first (SIGKILL: a worker deep in a task answers a polite
        close only when the task ends; whatever it was writing is atomic and redone)."""
        if abort:
            _quiet_shutdown()
        if abort and self.cluster is not None:
            for nanny in list(getattr(self.cluster, "workers", {}).values()):
                with contextlib.suppress(Exception):
                    pid = nanny.process.pid
                    if pid:
                        os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(Exception):
            self.client.close(timeout=CLOSE_TIMEOUT_S)
        if self.cluster is not None:
            with contextlib.suppress(Exception):
                self.cluster.close(timeout=CLOSE_TIMEOUT_S)


def _connect(address: str) -> Any:
    """A client of the scheduler at ``address``, within :data:`CONNECT_TIMEOUT_S`.

    Built in a thread: something that accepts the connection but is no Dask scheduler (a web
    server on that port) leaves distributed's handshake waiting past its own timeout.
    """
    from distributed import Client

    refused = _refused(address)
    if refused is not None:
        # distributed retries a refused connection until its timeout (29 s in a trial)
        raise OSError(
            f"scheduler {address}: no Dask scheduler answers there ({refused}); start one "
            "(`dask scheduler`, then `dask worker ADDRESS`) or use --scheduler local"
        )
    box: dict[str, Any] = {}

    def connect() -> None:
        try:
            box["client"] = Client(address, timeout=f"{CONNECT_TIMEOUT_S}s")
        except BaseException as exc:  # handed to the waiting thread
            box["error"] = exc

    thread = threading.Thread(target=connect, name="predisat-connect", daemon=True)
    thread.start()
    thread.join(CONNECT_TIMEOUT_S + 5.0)
    if thread.is_alive():
        raise OSError(
            f"scheduler {address}: something answers there, but no Dask scheduler (no "
            f"handshake in {CONNECT_TIMEOUT_S + 5.0:g} s); check the address and port (`dask "
            "scheduler` prints it) or use --scheduler local"
        )
    if isinstance(box.get("error"), OSError):
        raise OSError(
            f"scheduler {address}: no Dask scheduler answers there ({box['error']}); start one "
            "(`dask scheduler`, then `dask worker ADDRESS`) or use --scheduler local"
        ) from None
    error = box.get("error")
    if isinstance(error, Exception):
        # something answered with bytes that are no Dask handshake (an SSH, SMTP or FTP
        # banner, a proxy's reply): distributed read them as a frame length and failed with
        # a MemoryError allocating exabytes, or another error; told as a wrong address
        raise OSError(
            f"scheduler {address}: something answers there, but no Dask scheduler (its reply "
            f"is no Dask handshake: {type(error).__name__}: {str(error)[:160]}); check the "
            "address and port "
            "(`dask scheduler` prints it) or use --scheduler local"
        ) from None
    if error is not None:
        raise error
    return box["client"]


def _refused(address: str) -> str | None:
    """Why a TCP address refuses connections at once (nothing listens there), or None: anything
    else (an answer, a timeout, another scheme, a name that does not resolve) is left to
    distributed, which says more about it."""
    m = re.fullmatch(r"tcp://\[?([^\]]+?)\]?:(\d+)/?", address)
    if m is None:
        return None
    try:
        with socket.create_connection((m[1], int(m[2])), timeout=_REFUSED_PROBE_S):
            return None
    except ConnectionRefusedError as exc:
        return f"connection refused: {exc.strerror or exc}"
    except OSError:
        return None


# The code version each code_version function gave when this process first asked: the code a
# process runs is what it imported then. A long-lived worker kept the modules it imported before
# a `git pull` while a fresh hash of its files matched the client's (a user trial); a memo per
# process, not hidden state: it only ever holds the first answer.
_FIRST_SEEN: dict[Callable[[], str], str] = {}
_FIRST_SEEN_LOCK = threading.Lock()

# the folder holding this package: the checkout (predisat, locator, tests) or site-packages
_CHECKOUT = os.path.dirname(os.path.dirname(os.path.realpath(__file__))) + os.sep
# The folders of this code's packages. A process's code is these files as they were when it
# first imported this module (a worker: at its first contact with a run, whose check unpickles
# this module, or at its start, the local cluster's preload), not as they are when a code
# version is asked: the memo above is per function, and a worker that first served `predisat
# availability` (predisat's fingerprint) and, after a `git pull`, a `locator campaign` (both
# packages' fingerprint, first asked then) hashed the new files and passed while it ran the
# modules imported before the pull (a review: job files of the old error model under the new
# code's keys, intervals up to 267 m apart, exit 0). Stamping a module's file when a check first
# saw it loaded left a hole: a module a task imported (predisat.availability.network's task
# imports predisat.availability.run) that a `git pull` changed before the next check was stamped
# in its new state, and a command of the other fingerprint got the old module's results (p4).
_PACKAGES = tuple(
    _CHECKOUT + p + os.sep for p in ("predisat", "locator") if os.path.isdir(_CHECKOUT + p)
)


def _stamp(path: str) -> tuple[int, int]:
    try:
        st = os.stat(path)
    except OSError:
        return (-1, -1)
    return (st.st_mtime_ns, st.st_size)


def _package_files() -> dict[str, tuple[int, int]]:
    """The source and data files of the packages (what their fingerprints hash; no editor's
    swap or lock file) and their stamps."""
    out: dict[str, tuple[int, int]] = {}
    for root in _PACKAGES:
        for folder, dirs, files in os.walk(root):
            dirs[:] = [d for d in dirs if d != "__pycache__" and not d.startswith(".")]
            data = "data" in folder[len(root) :].split(os.sep)
            for f in files:
                if not f.startswith(".") and (f.endswith(".py") or data):
                    out[os.path.join(folder, f)] = _stamp(os.path.join(folder, f))
    return out


def _digest(path: str) -> str | None:
    try:
        with open(path, "rb") as f:
            return hashlib.sha256(f.read()).hexdigest()
    except OSError:
        return None


_STARTED_WITH = _package_files()  # the stamps when this process first imported this module
_START_DIGESTS: dict[str, str | None] = {}  # their contents, hashed at the first check
_VERDICTS: dict[str, tuple[tuple[int, int], bool]] = {}  # a stamp that differs: same content?
_RUNS_START: set[str] = set()  # files of modules first seen loaded while as at the start
_TAINTED: list[str] = []  # files of modules first seen loaded after they changed on disk
_REAL: dict[str, str] = {}  # a module's __file__: its real path


def _as_at_start(path: str) -> bool:
    """Whether a file of the packages has the content it had when this process started: its
    stamp then, or (a checkout switched and back, a file touched) the same bytes."""
    if not _START_DIGESTS:  # hashed once, at the first check: 4 MB, some 15 ms
        for p, st in _STARTED_WITH.items():
            _START_DIGESTS[p] = _digest(p) if _stamp(p) == st else None  # None: unknown
    st, st0 = _stamp(path), _STARTED_WITH.get(path)
    if st0 is None:  # added since
        return False
    if st == st0:
        return True
    seen = _VERDICTS.get(path)
    if seen is None or seen[0] != st:
        start = _START_DIGESTS.get(path)
        seen = (st, start is not None and _digest(path) == start)
        _VERDICTS[path] = seen
    return seen[1]


def _package_changes() -> list[str]:
    """Files of the packages added, removed or changed since this process started."""
    return [p for p in sorted(_package_files().keys() | _STARTED_WITH.keys())
            if not _as_at_start(p)]  # fmt: skip


# The (mtime ns, size) of the source file of every other module of this checkout (its tests,
# an environment inside it) this process had loaded when it was asked for a code version.
_SOURCE_STAMPS: dict[str, tuple[int, int]] = {}
_SEEN_FILES: set[str] = set()


def _changed_sources() -> list[str]:
    """Source files of the modules loaded here that changed since this process started (its
    packages' files) or since first stamped (the checkout's others); the modules loaded since
    the last call are stamped now. A module of the packages first seen loaded after its file
    changed is *tainted* (:data:`_TAINTED`): it may run the new file under an old code version."""
    import sys

    changed = [f for f, st in _SOURCE_STAMPS.items() if _stamp(f) != st]
    for mod in list(sys.modules.values()):
        f = getattr(mod, "__file__", None)
        if not (isinstance(f, str) and f.endswith(".py")):
            continue
        real = _REAL.get(f)
        if real is None:
            real = _REAL[f] = os.path.realpath(f)
        if real.startswith(_PACKAGES):
            if real in _RUNS_START or real in _TAINTED:
                if real in _RUNS_START and not _as_at_start(real):
                    changed.append(real)  # imported as at the start, changed since
            elif _as_at_start(real):
                _RUNS_START.add(real)
            else:  # imported before or after it changed: which code it runs is unknown
                _TAINTED.append(real)
        elif f not in _SEEN_FILES:
            _SEEN_FILES.add(f)
            if real.startswith(_CHECKOUT):  # this checkout's (or environment's)
                _SOURCE_STAMPS[f] = _stamp(f)
    return changed


def _version_here(code_version: Callable[[], str]) -> str:
    """``code_version()`` as this process first saw it (run here and on each worker); a value
    no client's fingerprint equals when the files of its code changed on disk before a code
    version is first asked (the process runs the modules it imported before), and, whatever
    was asked before, once a module first seen loaded after its file changed may run the new
    file (imported in a task, after a `git pull`)."""
    with _FIRST_SEEN_LOCK:  # keyed by the function itself (a module-level one unpickles as it)
        changed = _changed_sources()
        if _TAINTED:
            return (
                f"unknown: {len(_TAINTED)} module(s) it imported since it started changed on "
                f"disk, e.g. {_TAINTED[0]}"
            )
        if code_version not in _FIRST_SEEN:
            changed += [p for p in _package_changes() if p not in changed]
            value = code_version()
            if changed:
                value = (
                    f"{value[:16]}, but {len(changed)} file(s) of its code changed on disk "
                    f"since it started, e.g. {changed[0]}"
                )
            _FIRST_SEEN[code_version] = value
        return _FIRST_SEEN[code_version]


def _where_am_i() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except ValueError:  # not in a worker
        return "this process"


def _checked_task(
    fn: Callable[[S, T], R], code_version: Callable[[], str], expected: str, shared: S, item: T
) -> R:
    """``fn(shared, item)`` on a worker whose code is the client's: a worker that joined after
    the run's first check, or imported other code, refuses the task instead of computing it."""
    theirs = _version_here(code_version)
    if theirs != expected:
        raise OSError(
            f"worker {_where_am_i()} runs other code than this command (code {theirs}, here "
            f"{expected}); it joined after the run started or kept modules imported before an "
            "update: restart it from this environment or checkout and rerun the same command "
            "to resume (the work finished so far is kept)"
        )
    result = fn(shared, item)
    # the task may have imported a module changed on disk since the check (a `git pull` in
    # the middle of the run): its result is not taken for this code's
    theirs = _version_here(code_version)
    if theirs != expected:
        raise OSError(
            f"worker {_where_am_i()} ran a task with other code than this command (code "
            f"{theirs}, here {expected}): this code's files changed on disk during the run; "
            "restart the workers and rerun the same command to resume (the work finished so "
            "far is kept)"
        )
    return result


def _sees(paths: Sequence[str]) -> list[str]:
    """The paths of ``paths`` this process cannot see (run on each worker)."""
    return [p for p in paths if not os.path.exists(p)]


def _check_workers(
    client: Any, address: str, code_version: Callable[[], str] | None, paths: Sequence[str]
) -> None:
    """Refuse a cluster the run's tasks would go wrong on, before any task: no worker (they
    would wait for one forever), workers that cannot import this code or run other code
    (their results would be taken for this code's), workers that do not see the run's files
    (a survey's images "missing" on a worker gave masks all assumed, and kept them)."""
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except TimeoutError:
        raise OSError(
            f"scheduler {address}: no worker has joined it in {WORKER_WAIT_S:g} s; start workers "
            f"(`dask worker {address}`) or use --scheduler local"
        ) from None
    if code_version is not None:
        mine = _version_here(code_version)
        try:
            theirs = client.run(_version_here, code_version)
        except Exception as exc:  # a worker without this package cannot even unpickle it
            raise OSError(
                f"scheduler {address}: its workers cannot run this code ({type(exc).__name__}: "
                f"{exc}); start them where this version of predisat is installed (the same "
                "environment, or PYTHONPATH to the same checkout)"
            ) from None
        other = sorted(w for w, v in theirs.items() if v != mine)
        if other:
            raise OSError(
                f"scheduler {address}: {len(other)} of {len(theirs)} worker(s) run other code "
                f"than this command ({other[0]}: code {theirs[other[0]]}, here {mine}); their "
                "results would be taken for this code's: restart them from this environment "
                "or checkout (a worker keeps the code it imported before an update)"
            )
    local = [p for p in paths if "://" not in p]
    if local:
        unseen = {w: v for w, v in client.run(_sees, local).items() if v}
        if unseen:
            w, missing = next(iter(sorted(unseen.items())))
            raise OSError(
                f"scheduler {address}: {len(unseen)} worker(s) do not see {missing[0]} ({w}); "
                "give paths on a file system every worker mounts at the same place (or URLs, "
                "docs/cluster.md)"
            )


def _quiet_shutdown() -> None:
    """Silence distributed's loggers for the rest of an aborted process.

    After Ctrl-C (which a terminal also sends to the cluster's nanny processes) or an error,
    the comms of dying workers and of the closing scheduler break mid-message; their
    tracebacks are shutdown noise, not the user's error, and the run's own message says what
    happened and how to resume.
    """
    # their children too: dask's configuration gives some a level of their own
    # ("distributed.client": warning), which a parent's level does not override; the client's
    # reconnection to a scheduler killed mid-run, cancelled as the command closed it, printed
    # a 30-line traceback before the command's one line (a user trial)
    roots = ("distributed", "tornado", "asyncio")
    known = list(logging.Logger.manager.loggerDict)  # a copy: getLogger may add to it
    for name in {*roots, *(n for n in known if n.partition(".")[0] in roots)}:
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _not_a_task_error(record: logging.LogRecord) -> bool:
    """False for distributed's "Compute Failed" report of a task's own exception (the client
    raises that exception and the command prints it in one line; printed by the worker too, a
    full traceback came first on the terminal: a storage trial) and for a heartbeat that missed
    the closing or busy scheduler (a traceback in the middle of `predisat demo` on a loaded
    machine; a scheduler really lost ends the command in one line, ``_cluster_lost``)."""
    text = str(record.msg)
    return not text.startswith(("Compute Failed", "Failed to communicate with scheduler"))


def dask_setup(worker: object) -> None:
    """Preload hook of the local cluster's worker processes: they ignore SIGINT, and leave a
    task's error to the command that sent it.

    Ctrl-C in a terminal reaches every process of the group; this process alone handles it
    (it cancels the tasks and closes the cluster), so the workers must not die of it first.
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed.worker").addFilter(_not_a_task_error)


def _start_local_cluster(workers: int) -> Any:
    """A LocalCluster of ``workers`` processes (which ignore SIGINT: they start with it
    blocked, and :func:`dask_setup` ignores it).

    It is built in a thread while this one waits interruptibly: a Ctrl-C during the start
    leaves the half-built cluster to its thread, whose processes end with this one
    (distributed's worker processes exit when their parent does).
    """
    from multiprocessing import resource_tracker

    import dask
    from distributed import LocalCluster

    box: dict[str, Any] = {}

    def build() -> None:
        # the worker processes are started from threads this one starts, and inherit its
        # blocked SIGINT: a Ctrl-C that reaches them before their preload ignores it
        # (SIGINT goes to the whole process group) must not kill them mid-start. The
        # resource tracker is started first: starting it unblocks SIGINT in its caller.
        resource_tracker.ensure_running()
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        for attempt in range(_START_ATTEMPTS):
            try:
                with dask.config.set(
                    {"distributed.scheduler.allowed-failures": _ALLOWED_FAILURES}
                ):
                    box["cluster"] = LocalCluster(
                        n_workers=workers, threads_per_worker=1, processes=True,
                        host="127.0.0.1", dashboard_address="127.0.0.1:0",
                        silence_logs=logging.ERROR, preload=[__name__],
                    )  # fmt: skip
                return
            except RuntimeError as exc:  # "Nanny failed to start": a worker died starting
                if attempt == _START_ATTEMPTS - 1:
                    box["error"] = OSError(
                        f"the local Dask cluster of {workers} worker(s) did not start "
                        f"({_START_ATTEMPTS} attempts; last: {exc}); see the workers' "
                        "messages above, or run with --scheduler serial"
                    )
            except BaseException as exc:  # handed to the waiting thread
                box["error"] = exc
                return

    thread = threading.Thread(target=build, name="predisat-local-cluster", daemon=True)
    thread.start()
    while thread.is_alive():
        thread.join(0.1)
    if "error" in box:
        raise box["error"]
    return box["cluster"]


def _cluster_lost(exc: BaseException) -> bool:
    """Whether ``exc`` is distributed's way of saying the scheduler went away (a task's own
    error comes as itself): a user trial's stopped scheduler ended the run with three
    tracebacks and nothing on what was kept."""
    from asyncio import CancelledError as AsyncCancelled
    from concurrent.futures import CancelledError

    from distributed.comm.core import CommClosedError

    return isinstance(exc, CommClosedError) or (
        isinstance(exc, (CancelledError, AsyncCancelled)) and "connection-lost" in str(exc)
    )


def _identity(x: S) -> S:
    return x


class TaskRunner:
    """Runs a run's tasks where a :class:`Scheduler` says; a context manager (closes the
    cluster it started).

    Parameters
    ----------
    scheduler : Scheduler
    code_version : callable, optional
        A module-level function returning the fingerprint of the code the tasks run (e.g.
        :func:`predisat.codeversion.code_fingerprint`), taken as each process first gave it
        (the code it imported then): on a cluster by address, every worker's must equal this
        process's, or the run is refused before any task; on any cluster a worker whose code
        is other (one that joins later, a local worker started after a `git pull`) or whose
        files changed during a task refuses the task.
    paths : sequence of str
        Local files and folders the tasks read or write: on a cluster by address, a worker
        that does not see one refuses the run before any task. Relative paths are made
        absolute here (a worker resolves them in its own working folder).
    """

    def __init__(
        self,
        scheduler: Scheduler,
        code_version: Callable[[], str] | None = None,
        paths: Sequence[str | os.PathLike[str]] = (),
    ) -> None:
        self.scheduler = scheduler
        self.code_version = code_version
        self.paths = tuple(
            str(p) if "://" in str(p) else os.path.abspath(os.fspath(p)) for p in paths
        )
        self._ready: _ReadyCluster | None = None
        self._aborted = False  # a map ended by an exception (Ctrl-C, a task's error)

    def __enter__(self) -> TaskRunner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def parallel(self) -> bool:
        """Whether tasks may run side by side (threads or cluster workers)."""
        return self.scheduler.kind != "serial" or self.scheduler.workers > 1

    def client(self) -> Any:
        """The ``distributed.Client`` (started on first use); None when serial."""
        if self.scheduler.kind == "serial":
            return None
        if self._ready is None:
            self._ready = _ReadyCluster(self.scheduler, self.code_version, self.paths)
        return self._ready.client

    def map_unordered(
        self, fn: Callable[[S, T], R], shared: S, items: Sequence[T], name: str = "task"
    ) -> Iterator[R]:
        """``fn(shared, item)`` of every item, results as they finish (any order).

        ``fn`` must be a module-level function and ``shared`` and the items picklable on a
        cluster; ``shared`` is sent to the cluster once per call, not once per item. On an
        error or Ctrl-C the tasks not yet finished are cancelled before the exception goes on.
        """
        if not items:
            return
        if self.scheduler.kind == "serial":
            yield from self._map_here(fn, shared, items)
            return
        client = self.client()
        tag = f"predisat-{name}-{uuid.uuid4().hex[:8]}"
        # a task, not scattered data: if the worker holding it dies, it is computed again.
        # Its key's first word differs from the items' so that it forms a task group of its
        # own (dask.utils.key_split keeps the first word, then stops at a hex or 8-letter
        # one): in the items' group, the scheduler kept every item on the worker holding it
        shared_f = client.submit(_identity, shared, key=f"shared-{tag}")
        if self.code_version is not None:
            # workers may join after the first check, and a local cluster's start after this
            # process's fingerprint, or a task import a module changed on disk since: each task
            # checks its own, before and after it runs
            version = self.code_version
            expected = _version_here(version)
            futures = [
                client.submit(
                    _checked_task, fn, version, expected, shared_f, it, key=f"{tag}-{k}",
                    pure=False,
                )
                for k, it in enumerate(items)
            ]
        else:
            futures = [
                client.submit(fn, shared_f, it, key=f"{tag}-{k}", pure=False)
                for k, it in enumerate(items)
            ]
        from distributed import as_completed

        try:
            for fut in as_completed(futures):
                yield fut.result()
        except BaseException as exc:
            self._aborted = True
            _quiet_shutdown()
            if self.scheduler.kind == "address":  # a local cluster's workers are killed
                with contextlib.suppress(Exception):
                    client.cancel([*futures, shared_f], asynchronous=False)
            if _cluster_lost(exc):  # not a task's own error: say what is kept
                reason = str(exc).splitlines()[0] if str(exc) else ""
                raise OSError(
                    f"the {self.scheduler.describe()} was lost mid-run ({type(exc).__name__}: "
                    f"{reason}); the work finished so far is kept: restart the cluster (or "
                    "use --scheduler local) and rerun the same command to resume"
                ) from None
            raise
        finally:
            futures.clear()

    def _map_here(self, fn: Callable[[S, T], R], shared: S, items: Sequence[T]) -> Iterator[R]:
        if self.scheduler.workers == 1 or len(items) == 1:
            for it in items:
                yield fn(shared, it)
            return
        pool = ThreadPoolExecutor(self.scheduler.workers)
        pending: set[Future[R]] = {pool.submit(fn, shared, it) for it in items}
        try:
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    yield fut.result()
        finally:
            for fut in pending:
                fut.cancel()
            pool.shutdown(wait=True, cancel_futures=True)

    def close(self) -> None:
        """Close the client and the local cluster (each within :data:`CLOSE_TIMEOUT_S`)."""
        if self._ready is not None:
            ready, self._ready = self._ready, None
            try:
                ready.close(abort=self._aborted)
            except BaseException:  # Ctrl-C while closing politely: kill the workers, then go
                ready.close(abort=True)
                raise
