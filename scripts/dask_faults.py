"""Interrupt and kill ``predisat process`` at random times; check it ends, resumes and writes
the bytes of an uninterrupted run.

Usage::

    python scripts/dask_faults.py interrupt [--tries 100] [--schedulers serial,local]
    python scripts/dask_faults.py kill [--tries 20] [--targets worker,client]
        [--survey DIR] [--workers 2] [--seed 0] [--work DIR]

``interrupt``: Ctrl-C (SIGINT) at a random time of the run, to the process alone or, every
other try, to its whole process group as a terminal does (the cluster's workers too); the run
must end within ``--limit`` seconds (default 5) with exit code 130 and its resume message (or
have finished before the signal, exit 0). Every ``--verify-every``-th interrupted run is then
resumed and its files compared with the reference run's.

``kill``: SIGKILL at a random time of a ``--scheduler local`` run, of one worker process
(the run must still finish, exit 0) or of the client (the command itself; then the same
command is run again to resume). Either way the published files (``masks.parquet``,
``bad_frames.csv``, ``chunks/*``) must equal the uninterrupted serial run's byte for byte.
Every run pins its timestamps with ``SOURCE_DATE_EPOCH``.

Without ``--survey`` a small synthetic survey is made first (line 144, 200 m at 10 m, two
320x240 pinhole cameras, 42 frames, 4 chunks of 50 m). Prints one line per try and a summary;
exit code 1 when any try failed.
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[1]
RESUME_NOTE = "rerun the same command"  # to resume, or: nothing was written (in the imports)


def make_survey(work: Path) -> Path:
    """A small synthetic survey (200 m of line 144, 320x240 pinhole cameras)."""
    from predisat.camera.models import CameraModel
    from predisat.synth.generate import generate_survey
    from predisat.track.map import demo_track

    out = work / "synth"
    if not (out / "survey" / "manifest.csv").is_file():
        generate_survey(
            demo_track(), 3000.0, 3200.0, sky="mixed", seed=5, out_dir=out,
            camera=CameraModel.pinhole_from_fov(320, 240, 74.0), progress=False,
        )  # fmt: skip
    return out / "survey"


def command(survey: Path, out: Path, scheduler: str, workers: int, chunk_m: float) -> list[str]:
    cmd = [sys.executable, "-c", "import sys; from predisat.cli import main; sys.exit(main())",
           "process", str(survey), "--out", str(out), "--chunk-m", f"{chunk_m:g}",
           "--scheduler", scheduler, "--quiet"]  # fmt: skip
    if scheduler != "serial":
        cmd += ["--workers", str(workers)]
    return cmd


def environment() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["SOURCE_DATE_EPOCH"] = "1700000000"
    return env


def _default_sigint() -> None:
    # a job started in the background by a shell inherits SIGINT ignored, and Python then
    # installs no KeyboardInterrupt handler: the command must see Ctrl-C as at a terminal
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start(cmd: list[str]) -> subprocess.Popen[str]:
    # a session of its own: a signal to its group does not reach this script
    return subprocess.Popen(cmd, env=environment(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=_default_sigint)  # fmt: skip


def outputs(out: Path) -> dict[str, bytes]:
    """The files a run publishes, by path (not the cache, not provenance.json's timings)."""
    chunks = sorted(p for p in (out / "chunks").iterdir() if not p.name.startswith("."))
    files = [out / "masks.parquet", out / "bad_frames.csv", *chunks]
    return {str(f.relative_to(out)): f.read_bytes() for f in files if f.is_file()}


def run_to_end(cmd: list[str], timeout_s: float = 900.0) -> tuple[int, str, float]:
    t0 = time.perf_counter()
    proc = start(cmd)
    _, err = proc.communicate(timeout=timeout_s)
    return proc.returncode, err, time.perf_counter() - t0


def live_children(pids: list[int]) -> list[int]:
    return [p for p in pids if psutil.pid_exists(p) and psutil.Process(p).status() != "zombie"]


def interrupt(args: argparse.Namespace, survey: Path, work: Path) -> int:
    rng = random.Random(args.seed)
    failures = 0
    for scheduler in args.schedulers.split(","):
        ref = work / f"ref-{scheduler}"
        shutil.rmtree(ref, ignore_errors=True)
        # twice: the first run may compile and cache the numba kernels, and the signal is
        # timed over the length of a usual run
        for _ in range(2):
            shutil.rmtree(ref, ignore_errors=True)
            rc, err, full_s = run_to_end(command(survey, ref, scheduler, args.workers,
                                                 args.chunk_m))  # fmt: skip
            if rc != 0:
                print(f"{scheduler}: reference run failed (exit {rc}):\n{err}")
                return 1
        want = outputs(ref)
        waits: list[float] = []
        finished = 0
        for k in range(args.tries):
            out = work / f"int-{scheduler}-{k}"
            shutil.rmtree(out, ignore_errors=True)
            delay = rng.uniform(0.0, full_s)
            group = k % 2 == 1
            proc = start(command(survey, out, scheduler, args.workers, args.chunk_m))
            time.sleep(delay)
            kids = [c.pid for c in psutil.Process(proc.pid).children(recursive=True)] \
                if proc.poll() is None else []  # fmt: skip
            t_sig = time.perf_counter()
            if proc.poll() is None:
                if group:
                    os.killpg(proc.pid, signal.SIGINT)
                else:
                    proc.send_signal(signal.SIGINT)
            try:
                _, err = proc.communicate(timeout=args.limit * 6)
                wait_s = time.perf_counter() - t_sig
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.communicate()
                wait_s = float("inf")
                err = "(hung)"
            time.sleep(0.5)
            orphans = live_children(kids)
            ok_exit = (proc.returncode == 130 and "interrupted" in err and RESUME_NOTE in err) or (
                proc.returncode == 0
            )
            ok = ok_exit and wait_s <= args.limit and not orphans
            finished += proc.returncode == 0
            if proc.returncode != 0:
                waits.append(wait_s)
            verdict = "ok"
            if ok and args.verify_every and k % args.verify_every == 0:
                rc2, _, _ = run_to_end(command(survey, out, scheduler, args.workers,
                                                  args.chunk_m))  # fmt: skip
                same = rc2 == 0 and outputs(out) == want
                ok = ok and same
                verdict = "ok, resumed identical" if same else f"RESUME DIFFERS (exit {rc2})"
            if not ok:
                failures += 1
                tail = err.strip().splitlines()[-3:]
                verdict = (f"FAILED: exit {proc.returncode}, {wait_s:.1f} s, orphans {orphans}, "
                           f"{tail}")  # fmt: skip
            print(f"{scheduler} try {k:3d}: SIGINT to {'group' if group else 'process'} at "
                  f"{delay:5.2f} s of {full_s:.1f}: ended in {wait_s:.2f} s, exit "
                  f"{proc.returncode} - {verdict}", flush=True)  # fmt: skip
            shutil.rmtree(out, ignore_errors=True)
        finite = [w for w in waits if w != float("inf")] or [float("nan")]
        print(f"{scheduler}: {args.tries} tries, {len(waits)} interrupted ({finished} finished "
              f"before the signal): time to exit median {statistics.median(finite):.2f} s, max "
              f"{max(waits, default=float('nan')):.2f} s, limit {args.limit:g} s")  # fmt: skip
    print(f"interrupt: {failures} failure(s)")
    return 1 if failures else 0


def kill(args: argparse.Namespace, survey: Path, work: Path) -> int:
    rng = random.Random(args.seed)
    ref = work / "ref-serial"
    shutil.rmtree(ref, ignore_errors=True)
    rc, err, serial_s = run_to_end(command(survey, ref, "serial", 1, args.chunk_m))
    if rc != 0:
        print(f"reference run failed (exit {rc}):\n{err}")
        return 1
    want = outputs(ref)
    probe = work / "probe"
    shutil.rmtree(probe, ignore_errors=True)
    rc, err, full_s = run_to_end(command(survey, probe, "local", args.workers, args.chunk_m))
    if rc != 0 or outputs(probe) != want:
        print(f"uninterrupted local run differs from the serial one (exit {rc}):\n{err}")
        return 1
    print(f"reference: serial {serial_s:.1f} s, local cluster of {args.workers} {full_s:.1f} s; "
          f"{len(want)} files")  # fmt: skip
    failures = 0
    for target in args.targets.split(","):
        for k in range(args.tries):
            out = work / f"kill-{target}-{k}"
            shutil.rmtree(out, ignore_errors=True)
            delay = rng.uniform(0.2 * full_s, 0.9 * full_s)  # past the start, before the end
            proc = start(command(survey, out, "local", args.workers, args.chunk_m))
            time.sleep(delay)
            what = "finished first"
            kids: list[int] = []
            if proc.poll() is None:
                kids = [c.pid for c in psutil.Process(proc.pid).children(recursive=True)]
                workers = [c for c in kids if c != proc.pid]
                if target == "worker" and workers:
                    victim = rng.choice(workers)
                    os.kill(victim, signal.SIGKILL)
                    what = f"worker {victim} killed"
                elif target == "client":
                    proc.send_signal(signal.SIGKILL)
                    what = "client killed"
                else:
                    what = "no worker yet"
            _, err = proc.communicate(timeout=900)
            rc = proc.returncode
            time.sleep(1.0)
            orphans = live_children(kids) if target == "client" else []
            resumed = ""
            if target == "client" and rc != 0:
                rc, err, _ = run_to_end(command(survey, out, "local", args.workers, args.chunk_m))
                resumed = ", resumed"
            same = rc == 0 and outputs(out) == want
            ok = same and not orphans
            failures += not ok
            print(f"{target} try {k:2d}: at {delay:5.2f} s ({what}{resumed}): exit {rc}, "
                  f"{'identical' if same else 'DIFFERENT'}"
                  f"{f', orphans {orphans}' if orphans else ''}"
                  f"{'' if ok else ' - FAILED ' + str(err.strip().splitlines()[-3:])}",
                  flush=True)  # fmt: skip
            shutil.rmtree(out, ignore_errors=True)
    print(f"kill: {failures} failure(s)")
    return 1 if failures else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=["interrupt", "kill"])
    ap.add_argument("--survey", type=Path, help="survey folder (default: a small synthetic one)")
    ap.add_argument("--tries", type=int, help="tries per scheduler / target (100 / 20)")
    ap.add_argument("--schedulers", default="serial,local")
    ap.add_argument("--targets", default="worker,client")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--chunk-m", type=float, default=50.0)
    ap.add_argument("--limit", type=float, default=5.0, help="seconds an interrupt may take")
    ap.add_argument("--verify-every", type=int, default=10,
                    help="resume every N-th interrupted run and compare (0: never)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--work", type=Path, help="working folder (default: a temporary one)")
    args = ap.parse_args()
    if args.tries is None:
        args.tries = 100 if args.mode == "interrupt" else 20
    with tempfile.TemporaryDirectory(prefix="dask_faults_") as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        survey = args.survey or make_survey(work)
        return interrupt(args, survey, work) if args.mode == "interrupt" else kill(
            args, survey, work
        )


if __name__ == "__main__":
    sys.exit(main())
