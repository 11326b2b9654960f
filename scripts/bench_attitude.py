"""What rectifying each frame with the vehicle's attitude costs: the reconstruction of a canted
survey with its measured roll, against the same survey with the attitude ignored (every frame
level and sure, the pipeline before docs/reconstruction.md section 16).

Needs a work folder of ``scripts/eval_cant.py`` (its ``survey_measured`` and the segmentation
cache of ``masks_measured``). Both runs reuse that cache, so only the reconstruction is timed:
the ignoring run builds one rectifier per camera, the measured one one per 0.05 deg of roll
and pitch met. Runs alternate, ``--repeat`` times each; prints the median seconds and the
ratio.

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

import predisat.reconstruct.chunks as chunks
from predisat.reconstruct.attitude import level_attitudes
from predisat.reconstruct.batch import process_survey
from predisat.reconstruct.params import PipelineParams


def _run(work: Path, variant: str, scratch: Path) -> float:
    out = scratch / variant
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(work / "masks_measured" / "cache", out / "cache")
    saved = chunks.frame_attitudes
    if variant == "ignored":
        chunks.frame_attitudes = level_attitudes
    try:
        t0 = time.perf_counter()
        process_survey(work / "survey_measured", out, PipelineParams(), progress=False,
                       scheduler="serial")  # fmt: skip
        return time.perf_counter() - t0
    finally:
        chunks.frame_attitudes = saved


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, required=True, help="a scripts/eval_cant.py folder")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    times: dict[str, list[float]] = {"ignored": [], "measured": []}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeat):
            for variant in times:
                times[variant].append(_run(args.work, variant, Path(tmp)))
    level, measured = (statistics.median(times[v]) for v in ("ignored", "measured"))
    print(f"reconstruction, serial, median of {args.repeat}: attitude ignored {level:.1f} s, "
          f"measured roll {measured:.1f} s, ratio {measured / level:.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
