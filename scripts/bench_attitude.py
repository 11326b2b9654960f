"""What rectifying each frame with the vehicle's attitude costs: the reconstruction of a canted
survey with its measured roll, against the same survey read as level (docs/reconstruction.md,
section 16).

Needs a work folder of ``scripts/eval_cant.py`` (its ``survey_measured`` and ``survey_level``
and the segmentation cache of ``masks_measured``). Both runs reuse that cache, so only the
reconstruction is timed: the level run builds one rectifier per camera, the measured one one
per 0.05 deg of roll and pitch met. Runs alternate, ``--repeat`` times each; prints the
median seconds and the ratio.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/bench_attitude.py --work /tmp/cant_right
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

from predisat.reconstruct.batch import process_survey
from predisat.reconstruct.params import PipelineParams


def _run(work: Path, variant: str, scratch: Path) -> float:
    out = scratch / variant
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(work / "masks_measured" / "cache", out / "cache")
    t0 = time.perf_counter()
    process_survey(work / f"survey_{variant}", out, PipelineParams(), progress=False,
                   scheduler="serial")  # fmt: skip
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, required=True, help="a scripts/eval_cant.py folder")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    times: dict[str, list[float]] = {"level": [], "measured": []}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeat):
            for variant in times:
                times[variant].append(_run(args.work, variant, Path(tmp)))
    level, measured = (statistics.median(times[v]) for v in ("level", "measured"))
    print(f"reconstruction, serial, median of {args.repeat}: level {level:.1f} s, measured "
          f"roll {measured:.1f} s, ratio {measured / level:.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
