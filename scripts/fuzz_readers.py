"""Fuzz the file readers with a large budget and print the inputs run and failures per reader.

Usage::

    python scripts/fuzz_readers.py [--examples 100000] [--readers rinex_obs,sp3] [--seed 0]
                                   [--out fuzz_failures]

Each input is a valid seed file (``tests/fuzz/harness.py``: real excerpts from ``tests/data``
and files the writers make) damaged by one to four mutations drawn from a seeded random
generator; the reader must read it or refuse it with its named error naming the file
(``docs/fuzzing.md``). Any other exception is a failure: each distinct one (type and the
innermost frame of the project's code) is counted, printed once and its input saved under
``--out``. Meant to run on a schedule (the CI runs the same mutations through Hypothesis with
a small budget: ``tests/fuzz``). Exit code 1 when there is any failure.
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness lives in tests/

from tests.fuzz.harness import READERS, FuzzFailure, mutate, reader, run_one, targets


def _where(exc: BaseException) -> str:
    """The innermost frame of the project's code in ``exc``'s traceback: file:line."""
    cause = exc.__cause__ or exc
    frames = [f for f in traceback.extract_tb(cause.__traceback__)
              if "/predisat/" in f.filename or "/locator/" in f.filename]  # fmt: skip
    f = frames[-1] if frames else traceback.extract_tb(cause.__traceback__)[-1]
    return f"{Path(f.filename).name}:{f.lineno}"


def fuzz(
    name: str, examples: int, seed: int, out: Path | None, every: int = 0
) -> tuple[int, int, int, dict]:
    """Run ``examples`` inputs through reader ``name``.

    Returns
    -------
    tuple
        (inputs run, read, refused with a named error, {failure key: count}). With ``every``,
        a progress line each ``every`` inputs.
    """
    r = reader(name)
    rng = random.Random(f"{seed}-{name}")

    def draw(lo: int, hi: int) -> int:
        return rng.randint(lo, hi)

    ok = 0
    failures: dict[str, int] = {}
    with tempfile.TemporaryDirectory(dir="/dev/shm" if Path("/dev/shm").is_dir() else None) as t:
        for k in range(examples):
            if every and k and k % every == 0:
                print(f"  {name}: {k} inputs, {sum(failures.values())} failures", flush=True)
            s = r.seeds[draw(0, len(r.seeds) - 1)]
            files = targets(r, s)
            target = files[draw(0, len(files) - 1)]
            other = r.seeds[draw(0, len(r.seeds) - 1)]
            other_data = other[targets(r, other)[0]]
            data = mutate(s[target], draw, other_data)
            folder = Path(t) / f"in{k % 2}"
            if folder.exists():
                for p in sorted(folder.rglob("*"), reverse=True):
                    p.unlink() if p.is_file() else p.rmdir()
            try:
                ok += run_one(r, s, target, data, folder)
            except FuzzFailure as exc:
                key = f"{type(exc.__cause__).__name__} at {_where(exc)}"
                if key not in failures:
                    print(f"  {name}: new failure {key}: {exc}", flush=True)
                    if out is not None:
                        out.mkdir(parents=True, exist_ok=True)
                        keep = out / f"{name}-{len(failures)}-{target.replace('/', '_')}"
                        keep.write_bytes(data)
                failures[key] = failures.get(key, 0) + 1
    refused = examples - ok - sum(failures.values())
    return examples, ok, refused, failures


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--examples", type=int, default=100_000, help="inputs per reader")
    ap.add_argument("--readers", default=",".join(READERS), help="comma-separated names")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="folder for failing inputs")
    ap.add_argument("--progress", type=int, default=0, help="a line each N inputs (0: none)")
    args = ap.parse_args(argv)
    total = n_fail = 0
    print(f"{'reader':<12} {'inputs':>9} {'read':>9} {'refused':>9} {'failures':>8} {'s':>7}")
    for name in args.readers.split(","):
        t0 = time.perf_counter()
        n, ok, refused, failures = fuzz(name, args.examples, args.seed, args.out, args.progress)
        total += n
        n_fail += sum(failures.values())
        print(f"{name:<12} {n:>9} {ok:>9} {refused:>9} {sum(failures.values()):>8} "
              f"{time.perf_counter() - t0:>7.1f}", flush=True)  # fmt: skip
        for key, count in failures.items():
            print(f"    {count} x {key}")
    print(f"total inputs {total}, failures {n_fail}")
    return 1 if n_fail else 0


if __name__ == "__main__":
    raise SystemExit(main())
