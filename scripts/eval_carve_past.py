"""Side cameras carving past their half-space, off and on (docs/reconstruction.md, section 17).

Processes each survey twice from the same images, ``ReconstructionParams.carve_past_deg`` None
(the half-space only) then the default, and scores both against the survey's ray-cast truth:
false trust (trusted directions truly blocked / trusted), the worst position's, the positions
above 0.1 %, the sky lost (truly visible directions not trusted / visible) and the wall time of
``process_survey`` (serial within one process; run nothing else beside it). A segmentation
cache folder (``<masks>/cache`` of an earlier ``predisat process``) is copied first when given,
so that only the reconstruction runs.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_carve_past.py --work /tmp/past \\
        demo=demo_out/survey:demo_out/truth:demo_out/masks/cache \\
        curve=W/survey_measured:W/world/truth
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from predisat.reconstruct.batch import process_survey
from predisat.reconstruct.carving import ReconstructionParams
from predisat.reconstruct.evaluate import compare, load_truth, trust_counts
from predisat.reconstruct.params import PipelineParams


def _score(name: str, survey: Path, truth: Path, cache: Path | None, past: float | None,
           work: Path) -> str:  # fmt: skip
    out = work / f"{name}_{'off' if past is None else f'{past:g}'}"
    if out.exists():
        shutil.rmtree(out)
    if cache is not None:
        shutil.copytree(cache, out / "cache")
    p = PipelineParams()
    p = dataclasses.replace(
        p, reconstruction=dataclasses.replace(p.reconstruction, carve_past_deg=past)
    )
    t0 = time.perf_counter()
    masks = process_survey(survey, out, p, progress=False).masks
    took_s = time.perf_counter() - t0
    c = compare(masks, load_truth(truth))
    trusted, good, visible = trust_counts(c.mask_el_deg, c.truth_el_deg)
    ft_pos = (trusted - good).sum(axis=1) / np.maximum(trusted.sum(axis=1), 1)
    ft = 100 * (1 - good.sum() / trusted.sum()) if trusted.sum() else 0.0
    return (
        f"{name:>22} {'off' if past is None else f'{past:g} deg':>7} {ft:12.5f} "
        f"{100 * ft_pos.max():10.3f} {int((ft_pos > 1e-3).sum()):>5} of {ft_pos.size:<4} "
        f"{100 * (1 - good.sum() / visible.sum()):8.2f} {took_s:9.1f}"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("surveys", nargs="+", metavar="NAME=SURVEY:TRUTH[:CACHE]")
    ap.add_argument("--work", type=Path, required=True, help="scratch folder")
    args = ap.parse_args(argv)
    default = ReconstructionParams().carve_past_deg
    print(f"{'survey':>22} {'past':>7} {'false trust %':>12} {'worst pos %':>10} "
          f"{'pos > 0.1 %':>12} {'sky lost %':>8} {'process s':>9}", flush=True)  # fmt: skip
    for item in args.surveys:
        name, _, paths = item.partition("=")
        parts = [Path(x) for x in paths.split(":")]
        if not name or len(parts) not in (2, 3):
            ap.error(f"{item!r}: give NAME=SURVEY:TRUTH or NAME=SURVEY:TRUTH:CACHE")
        cache = parts[2] if len(parts) == 3 else None
        for past in (None, default):
            print(_score(name, parts[0], parts[1], cache, past, args.work), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
