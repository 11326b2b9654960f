"""Images a row off their manifest rows: what the capture-time check finds and what it saves.

For a synthetic survey (``predisat synth`` output: ``W/survey`` and ``W/truth``) already
processed once (its segmentation cache ``W/masks/cache`` is copied, so only the
reconstruction reruns), each variant of the manifest is processed and scored against the
ray-cast truth: false trust (share of the trusted directions the truth blocks, and the worst
position), sky lost, the frames each check set aside, and how many of the moved rows the
capture-time check found. Variants: as is; one camera's rows from row K on naming the image
one row later (a dropped image: ``drop``); rows K..K+L-1 only (a dropped then an extra
image: ``stretch``). Each moved variant runs with no check setting frames aside (the
behaviour before stop 46), with the cross-camera step check only (before stop 47), and with
both (docs/reconstruction.md, section 22).

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_capture.py W --work /tmp/eval_capture \\
        --variant drop:right:40 --variant stretch:right:60:30 --variant drop:left:115
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

import numpy as np
from eval_step import linked_copy, mask_scores


def moved_copy(src: Path, dst: Path, side: str, start: int, length: int | None) -> set[str]:
    """``src`` whose manifest rows of ``side`` from its ``start``-th (time order) on, ``length``
    of them (None: to the end, the last row dropped), name the image one row later; the moved
    rows' frame ids."""
    man = linked_copy(src, dst)
    rows = man.index[man.side == side][np.argsort(man.gps_s[man.side == side], kind="stable")]
    if length is None:
        moved = rows[start:-1]
        man.loc[moved, "image"] = man.loc[rows[start + 1 :], "image"].to_numpy()
        man = man.drop(index=rows[-1:])
    else:
        moved = rows[start : start + length]
        man.loc[moved, "image"] = man.loc[rows[start + 1 : start + length + 1], "image"].to_numpy()
    man.to_csv(dst / "manifest.csv", index=False)
    return set(man.frame_id[moved])


def score(survey_dir: Path, cache: Path, truth: Path, out: Path, checks: tuple[str, ...],
          moved: set[str]) -> str:  # fmt: skip
    """Process ``survey_dir`` with only ``checks`` (of ``capture``, ``step``) setting frames
    aside, and score its masks against ``truth``."""
    from predisat.reconstruct import batch

    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(cache, out / "cache")
    saved = batch._capture_bad_frames, batch._step_bad_frames
    t0 = time.perf_counter()
    try:
        if "capture" not in checks:
            batch._capture_bad_frames = lambda check: {}
        if "step" not in checks:
            batch._step_bad_frames = lambda step: {}
        result = batch.process_survey(survey_dir, out, progress=False)
    finally:
        batch._capture_bad_frames, batch._step_bad_frames = saved
    took = time.perf_counter() - t0
    ft, worst, lost = mask_scores(result.masks, truth)
    by_capture = {b.frame_id for b in result.bad_frames if b.stage == "capture"}
    n_step = sum(b.stage == "step" for b in result.bad_frames)
    found = f", {len(moved & by_capture)} of {len(moved)} moved rows" if moved else ""
    return (f"false trust {ft:.5f} % (worst position {worst:.2f} %), sky lost "
            f"{lost:.2f} %; set aside: capture {len(by_capture)}{found}, step {n_step} "
            f"({took:.0f} s)")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("world", type=Path, help="predisat synth output (survey/, truth/), processed")
    ap.add_argument("--cache", type=Path, help="its segmentation cache (default WORLD/masks/cache)")
    ap.add_argument("--work", type=Path, default=Path("/tmp/eval_capture"), help="scratch folder")
    ap.add_argument("--variant", action="append", default=[],
                    help="drop:SIDE:K or stretch:SIDE:K:L (rows in time order)")  # fmt: skip
    ap.add_argument("--modes", nargs="+", default=["none", "step", "both"],
                    choices=["none", "step", "both"],
                    help="which checks set frames aside in the moved variants")  # fmt: skip
    args = ap.parse_args()
    survey, truth = args.world / "survey", args.world / "truth"
    cache = args.cache or args.world / "masks" / "cache"
    print(f"as is: {score(survey, cache, truth, args.work / 'as_is', ('capture', 'step'), set())}")
    for k, spec in enumerate(args.variant):
        kind, side, *nums = spec.split(":")
        if kind not in ("drop", "stretch") or len(nums) != (1 if kind == "drop" else 2):
            raise SystemExit(f"--variant {spec!r}: give drop:SIDE:K or stretch:SIDE:K:L")
        length = int(nums[1]) if kind == "stretch" else None
        moved = moved_copy(survey, args.work / f"v{k}", side, int(nums[0]), length)
        for mode, checks, name in (("none", (), "no check"), ("step", ("step",), "step check only"),
                                   ("both", ("capture", "step"), "both checks")):  # fmt: skip
            if mode not in args.modes:
                continue
            got = score(args.work / f"v{k}", cache, truth, args.work / f"v{k}_out", checks, moved)
            print(f"{spec}, {name}: {got}")


if __name__ == "__main__":
    main()
