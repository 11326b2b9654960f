"""Time of ``import predisat`` and ``import locator`` (and the command lines) in a fresh
interpreter, this checkout against a baseline checkout, interleaved.

Usage::

    python scripts/bench_imports.py --baseline DIR [--repeat 15]

``DIR`` is another checkout (e.g. ``git worktree add /tmp/base 96cb9e9``). Each import runs in
a new process started in the checkout's folder (so that it imports that checkout's code), best
and median of ``--repeat`` runs per checkout, alternating, and the ratio baseline / this.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STATEMENTS = {
    "import predisat": "import predisat",
    "import locator": "import locator",
    "import predisat.cli.app": "import predisat.cli.app",
    "import locator.cli": "import locator.cli",
}
_TIMER = "import time; t = time.perf_counter(); {stmt}; print(time.perf_counter() - t)"


def _once(stmt: str, cwd: Path) -> float:
    out = subprocess.run([sys.executable, "-c", _TIMER.format(stmt=stmt)], cwd=cwd,
                         capture_output=True, text=True, check=True)  # fmt: skip
    return float(out.stdout.strip())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", type=Path, required=True, help="another checkout")
    ap.add_argument("--repeat", type=int, default=15, help="runs per checkout (default 15)")
    args = ap.parse_args(argv)
    base = args.baseline.resolve()
    print(f"{'statement':26} {'this med s':>10} {'base med s':>10} {'this min':>9} "
          f"{'base min':>9} {'base/this':>9}")  # fmt: skip
    for label, stmt in STATEMENTS.items():
        if label.endswith("app") and not (base / "predisat" / "cli" / "app.py").exists():
            stmt_base = "import predisat.cli"
        else:
            stmt_base = stmt
        mine, theirs = [], []
        for _ in range(args.repeat):
            mine.append(_once(stmt, ROOT))
            theirs.append(_once(stmt_base, base))
        m, b = statistics.median(mine), statistics.median(theirs)
        print(f"{label:26} {m:10.3f} {b:10.3f} {min(mine):9.3f} {min(theirs):9.3f} "
              f"{b / m:9.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
