"""Tests of predisat.scheduler: naming a scheduler, running tasks here and on a cluster."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from predisat.scheduler import Scheduler, TaskRunner, machine_workers


def scaled(shared: int, item: int) -> tuple[int, int]:
    return item, shared * item


def worker_of(shared: float, item: int) -> str:
    """The address of the worker that ran the task (after ``shared`` seconds of sleep)."""
    import time

    from distributed import get_worker

    time.sleep(shared)
    return str(get_worker().address)


def fails_on_three(shared: int, item: int) -> int:
    if item == 3:
        raise ValueError("item 3 is bad")
    return item


@pytest.fixture(scope="module")
def threads_cluster() -> Iterator[str]:
    """An in-process cluster (threads): quick to start; its scheduler's address."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0") as cluster:  # fmt: skip
        yield cluster.scheduler_address


def test_parse_names_the_three_kinds() -> None:
    assert Scheduler.parse(None) == Scheduler("serial", 1)
    assert Scheduler.parse(None, 1) == Scheduler("serial", 1)
    assert Scheduler.parse(None, 3) == Scheduler("local", 3)
    assert Scheduler.parse("serial", 2) == Scheduler("serial", 2)
    assert Scheduler.parse("Local") == Scheduler("local", machine_workers())
    assert Scheduler.parse("local", 4) == Scheduler("local", 4)
    assert Scheduler.parse("tcp://10.0.0.5:8786") == Scheduler("address", 0, "tcp://10.0.0.5:8786")
    assert Scheduler.parse("10.0.0.5:8786") == Scheduler("address", 0, "10.0.0.5:8786")
    assert machine_workers() == len(os.sched_getaffinity(0))
    with pytest.raises(ValueError, match="leave --workers out"):
        Scheduler.parse("tcp://10.0.0.5:8786", 2)
    # a mistyped 'local' was taken for a host and failed after the inputs were read
    for bad in ("", "  ", "--workers", "tcp://a b", "lcoal", "10.0.0.5", "host:port"):
        with pytest.raises(ValueError, match="not an address"):
            Scheduler.parse(bad)
    with pytest.raises(ValueError, match="workers must be >= 1"):
        Scheduler.local(0)


def test_serial_and_threads_give_every_result() -> None:
    items = list(range(20))
    want = {(i, 3 * i) for i in items}
    with TaskRunner(Scheduler.serial()) as runner:
        assert list(runner.map_unordered(scaled, 3, items)) == sorted(want)  # in order
        assert not runner.parallel and runner.client() is None
    with TaskRunner(Scheduler.serial(3)) as runner:
        assert set(runner.map_unordered(scaled, 3, items)) == want and runner.parallel
        with pytest.raises(ValueError, match="item 3 is bad"):
            list(runner.map_unordered(fails_on_three, 0, items))
    assert list(TaskRunner(Scheduler.serial()).map_unordered(scaled, 3, [])) == []


def test_a_cluster_by_address_runs_the_same_tasks(threads_cluster: str) -> None:
    items = list(range(30))
    with TaskRunner(Scheduler.parse(threads_cluster)) as runner:
        got = list(runner.map_unordered(scaled, 7, items, "test"))
        assert sorted(got) == [(i, 7 * i) for i in items]
        with pytest.raises(ValueError, match="item 3 is bad"):
            list(runner.map_unordered(fails_on_three, 0, items))
        client = runner.client()
    assert client.status == "closed"  # the runner closed its client, not the cluster


def test_the_tasks_of_a_map_spread_over_the_workers(threads_cluster: str) -> None:
    # the shared value is a task every item depends on; were it in the items' task group
    # (dask.utils.key_split of its key), the scheduler would keep every item on its worker
    # (an 8-letter name such as "campaign" ends key_split's group name early: covered too)
    for name in ("spread", "campaign"):
        with TaskRunner(Scheduler.parse(threads_cluster)) as runner:
            used = list(runner.map_unordered(worker_of, 0.2, list(range(8)), name))
            workers = runner.client().scheduler_info()["workers"]
        assert len(workers) == 2 and set(used) == set(workers), name


def test_an_address_where_no_scheduler_answers_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    import predisat.scheduler as sched

    monkeypatch.setattr(sched, "CONNECT_TIMEOUT_S", 1.0)

    with socket.socket() as s:  # a free port: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    runner = TaskRunner(Scheduler.at(f"tcp://127.0.0.1:{port}"))
    with pytest.raises(OSError, match=f"127.0.0.1:{port}.*--scheduler local"):
        runner.client()
    # told by a plain connect, before distributed retries until its timeout (29 s in a trial)
    calls: list[str] = []
    monkeypatch.setattr("distributed.Client", lambda *a, **k: calls.append("client"))
    with pytest.raises(OSError, match="connection refused"):
        TaskRunner(Scheduler.at(f"tcp://127.0.0.1:{port}")).client()
    assert calls == []


def test_a_local_cluster_whose_start_fails_is_started_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A worker killed while the cluster starts fails the start ("Nanny failed to start"):
    tried again, and refused with a message after three failures."""
    import distributed

    import predisat.scheduler as sched

    starts: list[dict] = []

    class FailingTwice:
        def __init__(self, **kwargs: object) -> None:
            starts.append(kwargs)
            if len(starts) <= fails:
                raise RuntimeError("Nanny failed to start.")

    monkeypatch.setattr(distributed, "LocalCluster", FailingTwice)
    fails = 2
    assert isinstance(sched._start_local_cluster(2), FailingTwice) and len(starts) == 3
    assert starts[0]["n_workers"] == 2 and starts[0]["preload"] == ["predisat.scheduler"]
    starts.clear()
    fails = 3
    with pytest.raises(OSError, match=r"did not start.*--scheduler serial"):
        sched._start_local_cluster(2)
    assert len(starts) == 3


def _sigint_state(pid: int) -> tuple[bool, bool]:
    """Whether SIGINT is (blocked, ignored) in process ``pid``, from /proc."""
    fields = dict(
        line.split(":\t", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
    )
    bit = 1 << (signal.SIGINT - 1)
    return bool(int(fields["SigBlk"], 16) & bit), bool(int(fields["SigIgn"], 16) & bit)


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
def test_local_workers_start_with_ctrl_c_blocked() -> None:
    """A terminal's Ctrl-C reaches the whole group, the workers too: one that arrives while a
    worker imports, before its preload ignores SIGINT, killed it and failed the start (a
    flaky CI run). The workers are born with SIGINT blocked (the resource tracker, which
    unblocks it in the thread that starts it, is started first); this process is not."""
    import psutil

    import predisat.scheduler as sched

    cluster = sched._start_local_cluster(1)
    try:
        workers = [
            p for p in psutil.Process().children(recursive=True)
            if "spawn_main" in " ".join(p.cmdline())
        ]  # fmt: skip
        assert len(workers) == 1
        assert _sigint_state(workers[0].pid) == (True, True)
        assert not _sigint_state(os.getpid())[0]  # ignored if the suite runs in background
    finally:
        cluster.close()


def code_version_of_this_process() -> str:
    """The "code version" a worker reports: its environment's, so that workers can differ."""
    return os.environ.get("PREDISAT_TEST_CODE", "client")


def test_a_cluster_by_address_is_checked_before_any_task(
    threads_cluster: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Workers that run other code, or do not see the run's files, returned wrong masks with
    exit 0 in a user trial (a relative survey folder, an old checkout): refused up front."""
    runner = TaskRunner(Scheduler.at(threads_cluster), code_version=code_version_of_this_process,
                        paths=[str(tmp_path)])  # fmt: skip
    assert runner.client() is not None  # same code, sees the folder
    runner.close()
    missing = tmp_path / "not-here"
    runner = TaskRunner(Scheduler.at(threads_cluster), paths=[str(missing)])
    with pytest.raises(OSError, match=rf"2 worker\(s\) do not see {missing}"):
        runner.client()
    # a relative path is made absolute in this process: a worker's own folder is another
    monkeypatch.chdir(tmp_path)
    assert TaskRunner(Scheduler.at(threads_cluster), paths=["x"]).paths == (str(tmp_path / "x"),)


def test_workers_running_other_code_are_refused() -> None:
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address="127.0.0.1:0",
                      env={"PREDISAT_TEST_CODE": "worker"}) as cluster:  # fmt: skip
        runner = TaskRunner(Scheduler.at(cluster.scheduler_address),
                            code_version=code_version_of_this_process)  # fmt: skip
        with pytest.raises(OSError, match=r"1 of 1 worker\(s\) run other code.*code worker, "
                           r"here client.*restart them"):  # fmt: skip
            runner.client()


def test_a_scheduler_without_workers_or_a_server_that_is_none_is_named(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from distributed import LocalCluster

    import predisat.scheduler as sched

    monkeypatch.setattr(sched, "WORKER_WAIT_S", 1.0)
    with LocalCluster(n_workers=0, processes=False, dashboard_address="127.0.0.1:0") as cluster:
        runner = TaskRunner(Scheduler.at(cluster.scheduler_address))
        with pytest.raises(OSError, match=r"no worker has joined it in 1 s.*dask worker"):
            runner.client()
    # something that accepts the connection and never answers (a web server's port): the
    # handshake used to wait forever
    monkeypatch.setattr(sched, "CONNECT_TIMEOUT_S", 1.0)
    with _server() as port:
        with pytest.raises(OSError, match=f"127.0.0.1:{port}: something answers there, but no "
                           "Dask scheduler"):  # fmt: skip
            TaskRunner(Scheduler.at(f"tcp://127.0.0.1:{port}")).client()


@contextlib.contextmanager
def _server(banner: bytes = b"") -> Iterator[int]:
    """A local TCP server that is no Dask scheduler: it accepts every connection and sends
    ``banner`` (nothing: it never answers); yields its port."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    accepted: list[socket.socket] = []

    def serve() -> None:
        while True:
            try:
                c = server.accept()[0]
            except OSError:
                return
            accepted.append(c)
            if banner:
                c.sendall(banner)

    threading.Thread(target=serve, daemon=True).start()
    try:
        yield server.getsockname()[1]
    finally:
        for c in accepted:
            c.close()
        server.close()


def test_a_scheduler_lost_mid_run_is_one_message_saying_the_work_is_kept() -> None:
    """A user trial's stopped scheduler ended the run with three tracebacks and nothing on
    what was kept (FutureCancelledError ... scheduler-connection-lost)."""
    import threading

    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                           dashboard_address="127.0.0.1:0")  # fmt: skip
    runner = TaskRunner(Scheduler.at(cluster.scheduler_address))
    got: list[str] = []
    threading.Timer(2.0, cluster.close).start()
    try:
        with pytest.raises(OSError, match=r"was lost mid-run .*work finished so far is kept.*"
                           r"rerun the same command"):  # fmt: skip
            for res in runner.map_unordered(worker_of, 0.5, list(range(40))):
                got.append(res)
    finally:
        runner.close()
        cluster.close()
    assert 0 < len(got) < 40


def _set_test_code(value: str) -> None:
    os.environ["PREDISAT_TEST_CODE"] = value


def test_a_worker_that_joins_later_or_kept_old_modules_refuses_its_tasks() -> None:
    """The first check sees the workers present then; a worker that joined later ran tasks of
    any code. And a long-lived worker's files can be updated under modules it imported before
    (a fresh hash of its files matched the client's, a user trial): the version a process first
    gave is the one it runs."""
    import subprocess
    import sys
    import time

    from distributed import Client, LocalCluster

    import predisat.scheduler as sched

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address="127.0.0.1:0",
                      env={"PREDISAT_TEST_CODE": "client"}) as cluster:  # fmt: skip
        address = cluster.scheduler_address
        with TaskRunner(Scheduler.at(address), code_version=code_version_of_this_process) as r:
            assert sorted(r.map_unordered(scaled, 3, [1, 2])) == [(1, 3), (2, 6)]
            # the worker's files "updated": a fresh answer now differs, the first one holds
            client: Client = r.client()
            client.run(_set_test_code, "updated")
            assert set(client.run(code_version_of_this_process).values()) == {"updated"}
            assert set(client.run(sched._version_here, code_version_of_this_process).values()) \
                == {"client"}  # fmt: skip
            # a worker of other code joins, and the first one leaves: the tasks go to it
            env = {**os.environ, "PREDISAT_TEST_CODE": "late"}
            late = subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "1",
                 "--nthreads", "1", "--no-dashboard"],
                env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )  # fmt: skip
            try:
                first = set(client.scheduler_info()["workers"])
                deadline = time.monotonic() + 60
                while len(client.scheduler_info()["workers"]) < 2:
                    assert time.monotonic() < deadline, "the late worker did not join"
                    time.sleep(0.2)
                client.retire_workers(list(first), close_workers=True)
                with pytest.raises(OSError, match=r"worker tcp://\S+ runs other code than this "
                                   r"command \(code late, here client\).*restart it"):  # fmt: skip
                    list(r.map_unordered(scaled, 3, [1, 2]))
            finally:
                late.terminate()
                late.wait(30)


def failing(shared: int, item: int) -> int:
    raise ValueError(f"item {item} is bad")


def test_a_tasks_error_reaches_the_command_once_without_the_workers_traceback(
    capfd: pytest.CaptureFixture[str],
) -> None:
    """A local worker printed distributed's "Compute Failed" traceback before the command's
    one-line error (a storage trial)."""
    with TaskRunner(Scheduler.local(1)) as runner, pytest.raises(ValueError, match="item 1"):
        list(runner.map_unordered(failing, 0, [1]))
    err = capfd.readouterr().err
    assert "Compute Failed" not in err and "Traceback" not in err


def test_local_workers_drop_only_the_logs_the_command_says_better() -> None:
    import logging

    from predisat.scheduler import _not_a_task_error

    def record(msg: str) -> logging.LogRecord:
        return logging.LogRecord("distributed.worker", logging.ERROR, "w.py", 1, msg, None, None)

    assert not _not_a_task_error(record("Compute Failed\nKey: x"))
    assert not _not_a_task_error(record("Failed to communicate with scheduler during heartbeat."))
    assert _not_a_task_error(record("Worker is at 95% memory usage. Pausing worker."))


def test_an_address_whose_server_sends_a_banner_is_named_not_a_traceback() -> None:
    """An SSH, SMTP or FTP server (or a proxy) at the address sends bytes first: distributed
    read them as a frame length and the command ended in a 70-line traceback, a MemoryError
    allocating exabytes."""
    with _server(b"SSH-2.0-OpenSSH_9.6p1 Ubuntu-3ubuntu13\r\n") as port:
        with pytest.raises(OSError, match=f"127.0.0.1:{port}: something answers there, but no "
                           "Dask scheduler"):  # fmt: skip
            TaskRunner(Scheduler.at(f"tcp://127.0.0.1:{port}")).client()


def test_an_aborted_run_silences_the_dask_loggers_with_a_level_of_their_own() -> None:
    """dask's configuration sets "distributed.client" to warning: silencing "distributed"
    left it logging the cancelled reconnection to a scheduler killed mid-run, a 30-line
    traceback before the command's one line (a user trial)."""
    import logging

    import distributed  # noqa: F401  (sets the configured levels)

    import predisat.scheduler as sched

    names = [n for n in list(logging.Logger.manager.loggerDict)
             if n.partition(".")[0] in ("distributed", "tornado", "asyncio")]  # fmt: skip
    saved = {n: logging.getLogger(n).level for n in {*names, "distributed.client"}}
    try:
        logging.getLogger("distributed.client").setLevel(logging.WARNING)  # dask's default
        sched._quiet_shutdown()
        for n in names:
            assert not logging.getLogger(n).isEnabledFor(logging.CRITICAL), n
    finally:
        for n, level in saved.items():
            logging.getLogger(n).setLevel(level)


def _code_a() -> str:
    return "code-a"


def _code_b() -> str:
    return "code-b"


def _code_c() -> str:
    return "code-c"


def test_a_code_version_first_asked_after_an_update_does_not_match(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A long-lived worker first asked for one code version (predisat's, by `availability`),
    then, after a `git pull` changed a module it had imported, for another (`locator
    campaign`'s, covering both packages): the fresh hash of the new files matched the client's
    while the worker ran the old module (job files of the old error model under the new keys).
    A file touched, or rewritten with the same bytes (a checkout switched and back), is no
    change."""
    import predisat.scheduler as sched

    monkeypatch.setattr(sched, "_FIRST_SEEN", {})
    monkeypatch.setattr(sched, "_VERDICTS", {})
    assert sched._version_here(_code_a) == "code-a"  # stamps the loaded modules
    module = os.path.realpath(sched.__file__)
    assert module in sched._RUNS_START
    st = os.stat(module)
    try:
        os.utime(module, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))  # touched
        assert sched._version_here(_code_a) == "code-a"
        assert sched._version_here(_code_b) == "code-b"  # the same bytes: no refusal
        # "updated": as if the file had other bytes when this process imported it
        monkeypatch.setitem(sched._START_DIGESTS, module, "another version's")
        monkeypatch.setattr(sched, "_VERDICTS", {})
        assert sched._version_here(_code_a) == "code-a"  # the first answer holds
        theirs = sched._version_here(_code_c)
        assert theirs != "code-c" and "changed on disk" in theirs and module in theirs, theirs
    finally:
        os.utime(module, ns=(st.st_atime_ns, st.st_mtime_ns))


def test_a_module_first_imported_after_its_file_changed_makes_the_code_unknown(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A module a task imports (predisat.availability.network's task imports
    predisat.availability.run) after a `git pull` changed it runs the new file under the code
    version the process gave before: whatever was asked, the code is unknown from then on."""
    import importlib
    import sys

    import predisat.scheduler as sched

    pkg = tmp_path / "p4_probe_pkg"  # stands for a package of this code
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "lazy.py").write_text('VALUE = "old"\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(sched, "_CHECKOUT", str(tmp_path) + os.sep)
    monkeypatch.setattr(sched, "_PACKAGES", (str(pkg) + os.sep,))
    empty: list[tuple[str, object]] = [
        ("_FIRST_SEEN", {}), ("_START_DIGESTS", {}), ("_VERDICTS", {}), ("_RUNS_START", set()),
        ("_TAINTED", []), ("_SOURCE_STAMPS", {}), ("_SEEN_FILES", set()),
    ]  # fmt: skip
    for name, value in empty:
        monkeypatch.setattr(sched, name, value)
    monkeypatch.setattr(sched, "_STARTED_WITH", sched._package_files())  # "started"
    try:
        importlib.import_module("p4_probe_pkg")
        assert sched._version_here(_code_a) == "code-a"
        (pkg / "lazy.py").write_text('VALUE = "new!"\n')  # a `git pull` during the run
        assert importlib.import_module("p4_probe_pkg.lazy").VALUE == "new!"  # a task's import
        for code in (_code_a, _code_b):
            theirs = sched._version_here(code)
            assert theirs.startswith("unknown") and str(pkg / "lazy.py") in theirs, theirs
    finally:
        sys.modules.pop("p4_probe_pkg.lazy", None)
        sys.modules.pop("p4_probe_pkg", None)


def lazy_probe(shared: None, item: int) -> str:
    """The value of a module of the package that only the task imports."""
    import importlib

    return str(importlib.import_module("predisat._probe").VALUE)


def test_a_worker_refuses_a_run_after_a_module_its_task_imported_changed(
    tmp_path: Path,
) -> None:
    """A long-lived worker imported a module of the package inside a task (as
    predisat.availability.network's task imports predisat.availability.run) and a `git pull`
    changed it: a command whose code version the worker had not been asked before (`locator
    campaign` after `availability`) matched the fresh hash of the new files, and its task gave
    the old module's result where a serial run gives the new one (p4)."""
    import shutil
    import subprocess
    import sys

    from distributed import Client, LocalCluster

    import predisat.scheduler as sched

    # the worker runs a copy of the package (its own files to change), with a module only the
    # task imports
    checkout = tmp_path / "checkout"
    (checkout / "predisat").mkdir(parents=True)
    here = Path(sched.__file__).parent
    for name in ("__init__.py", "scheduler.py"):
        shutil.copy(here / name, checkout / "predisat" / name)
    probe = checkout / "predisat" / "_probe.py"
    probe.write_text('VALUE = "old"\n')
    tests_root = Path(__file__).resolve().parents[2]  # the `tests` package for the task
    env = {**os.environ, "PYTHONPATH": str(tests_root)}
    with LocalCluster(n_workers=0, processes=False, protocol="tcp", host="127.0.0.1",
                      dashboard_address="127.0.0.1:0") as cluster:  # fmt: skip
        address = cluster.scheduler_address
        worker = subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "1",
             "--nthreads", "1", "--no-dashboard"],
            cwd=checkout, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        try:
            with Client(address) as client:
                client.wait_for_workers(1, timeout=60)
            with TaskRunner(Scheduler.at(address), code_version=_code_a) as r:
                assert list(r.map_unordered(lazy_probe, None, [0])) == ["old"]
            probe.write_text('VALUE = "new!"\n')  # a `git pull`
            with TaskRunner(Scheduler.at(address), code_version=_code_b) as r:
                with pytest.raises(OSError, match=r"1 of 1 worker\(s\) run other code.*"
                                   r"changed on disk.*_probe\.py"):  # fmt: skip
                    list(r.map_unordered(lazy_probe, None, [0]))
        finally:
            worker.terminate()
            worker.wait(30)
