"""Cameras out of step: what the cross-camera check sees on surveys in step and shifted.

For each survey given as ``SURVEY:CACHE`` (a survey folder and the segmentation cache of an
earlier ``predisat process``, its ``out/cache``), prints for each pair of cameras that share
directions the disagreement at lags -3..3 over the whole survey and the stretches
:func:`predisat.reconstruct.step.step_lags` calls off step (at each ``--switch-cost``); with
``--shift N --from K`` the same for the survey whose second camera's labels are taken N frames
late from position K on (the effect of a dropped image in its manifest column), so that the
check's margin against a false alarm and its reach can be read side by side
(docs/reconstruction.md, section 21).

With ``--truth TRUTH --work DIR`` (the generator's output folder and a scratch folder), the
survey and a copy whose manifest gives the second camera's rows, from row K on, the images N
rows later (a dropped image) are processed (the cache copied) and scored against the ray-cast
truth, the copy also with the check's set-aside frames kept (the behaviour before the check).

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_step.py --shift 1 --from 10 \\
        demo_out/survey:demo_out/masks/cache
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from predisat.masks.maskset import MaskSet
from predisat.reconstruct.framecache import decode_cache
from predisat.reconstruct.step import (
    SWITCH_COST,
    lag_disagreement,
    off_step,
    overlap_pixels,
    step_lags,
    widen,
)
from predisat.survey import Survey


def labels(survey: Survey, seg: Path, side: str, pix: tuple[np.ndarray, np.ndarray],
           times: np.ndarray) -> list[np.ndarray | None]:  # fmt: skip
    """A camera's labels of the shared directions at each of ``times`` (None: no frame)."""
    fr = survey.frames
    at = {round(float(fr.gps_s[i]), 3): i for i in np.flatnonzero(fr.side == side)}
    out: list[np.ndarray | None] = []
    for t in times:
        i = at.get(round(float(t), 3))
        path = None if i is None else seg / f"{fr.frame_id[i]}.npz"
        if path is None or not path.is_file():
            out.append(None)
            continue
        with np.load(path) as z:
            got = decode_cache(z, json.loads(str(z["meta"])), str(fr.frame_id[i]))
        out.append(got[0][pix] if isinstance(got, tuple) else None)
    return out


def linked_copy(src: Path, dst: Path) -> pd.DataFrame:
    """``dst`` made afresh with everything of the survey ``src`` linked but its manifest,
    which is returned to be edited and written there."""
    if dst.exists():
        shutil.rmtree(dst)
    dst.mkdir(parents=True)
    for p in src.iterdir():
        if p.name != "manifest.csv":
            (dst / p.name).symlink_to(p.resolve())
    return pd.read_csv(src / "manifest.csv")


def mask_scores(masks: MaskSet, truth: Path) -> tuple[float, float, float]:
    """False trust, its worst position's and sky lost of ``masks`` against the ray-cast
    ``truth``, percent."""
    from predisat.reconstruct.evaluate import (
        compare,
        load_truth,
        position_false_trust,
        trust_counts,
    )

    c = compare(masks, load_truth(truth))
    trusted, good, visible = trust_counts(c.mask_el_deg, c.truth_el_deg)
    ft = 100.0 * (1.0 - good.sum() / trusted.sum()) if trusted.sum() else 0.0
    lost = 100.0 * (1.0 - good.sum() / visible.sum())
    return ft, 100.0 * float(np.max(position_false_trust(c))), lost


def shifted_copy(src: Path, dst: Path, side: str, start: int, shift: int) -> Path:
    """``src`` whose manifest rows of ``side`` from its ``start``-th on (time order) name the
    images ``shift`` rows later; the last ``shift`` rows are dropped (images linked)."""
    man = linked_copy(src, dst)
    rows = man.index[man.side == side][np.argsort(man.gps_s[man.side == side], kind="stable")]
    moved = rows[start:]
    man.loc[moved[: len(moved) - shift], "image"] = man.loc[moved[shift:], "image"].to_numpy()
    man.drop(index=moved[len(moved) - shift :]).to_csv(dst / "manifest.csv", index=False)
    return dst


def score(survey_dir: Path, cache: Path, truth: Path, out: Path, keep: bool = False) -> str:
    """False trust and sky lost of ``survey_dir``'s masks against ``truth`` (``keep``: the
    step check's frames not set aside)."""
    from predisat.reconstruct import batch

    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(cache, out / "cache")
    set_aside = batch._step_bad_frames
    try:
        if keep:
            batch._step_bad_frames = lambda step: {}
        result = batch.process_survey(survey_dir, out, progress=False)
    finally:
        batch._step_bad_frames = set_aside
    ft, worst, lost = mask_scores(result.masks, truth)
    n_step = sum(b.stage == "step" for b in result.bad_frames)
    return (f"false trust {ft:.5f} % (worst position {worst:.2f} %), sky lost {lost:.2f} %, "
            f"{n_step} frames set aside by the step check")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("surveys", nargs="+", help="SURVEY:CACHE pairs")
    ap.add_argument("--shift", type=int, default=0, help="frames the second camera is late")
    ap.add_argument("--from", dest="start", type=int, default=0, help="first shifted position")
    ap.add_argument("--switch-cost", type=float, nargs="+", default=[SWITCH_COST])
    ap.add_argument("--truth", type=Path, help="the generator's output folder: score the masks")
    ap.add_argument("--work", type=Path, default=Path("/tmp/eval_step"), help="scratch folder")
    args = ap.parse_args()
    for pair in args.surveys:
        sdir, cache = (Path(p) for p in pair.split(":"))
        seg = cache if cache.name.startswith("seg-") else next(cache.glob("seg-*"))
        survey = Survey.load(sdir, check_images=False, on_error="skip")
        times = np.unique(np.round(np.asarray(survey.frames.gps_s, float), 3))
        sides = sorted(survey.cameras)
        for a_i, a in enumerate(sides):
            for b in sides[a_i + 1 :]:
                ca, cb = survey.cameras[a], survey.cameras[b]
                pa, pb = overlap_pixels(ca.camera, ca.mount, cb.camera, cb.mount)
                if pa[0].size < 50:
                    print(f"{sdir} {a}/{b}: {pa[0].size} shared directions, not compared")
                    continue
                la, lb = labels(survey, seg, a, pa, times), labels(survey, seg, b, pb, times)
                runs = {"as is": lb}
                if args.shift:
                    k, s = args.start, args.shift
                    k = min(k, len(lb))
                    late = lb[:k] + lb[k + s :] + [None] * min(s, len(lb) - k)
                    runs[f"{b} {s} late from {k}"] = late
                for name, lbs in runs.items():
                    d = lag_disagreement(la, lbs)
                    ok = np.all(np.isfinite(d), axis=1)
                    whole = 100 * d[ok].mean(axis=0)
                    print(f"{sdir} {a}/{b} ({pa[0].size} directions, {len(times)} positions), "
                          f"{name}: lags -3..3 " + " ".join(f"{x:.2f}" for x in whole) + " %")
                    for cost in args.switch_cost:
                        runs_off = widen(d, off_step(step_lags(d, cost)), cost)
                        print(f"    switch cost {cost}: "
                              + (", ".join(f"positions {r.first}-{r.last} lag {r.lag:+d}"
                                           for r in runs_off) or "in step"))

        if args.truth is not None:
            second = sorted(survey.cameras)[1]
            print(f"{sdir} as is: {score(sdir, cache, args.truth, args.work / 'as_is')}")
            if args.shift:
                late_dir = shifted_copy(sdir, args.work / "late", second, args.start, args.shift)
                tag = f"{second} {args.shift} late from {args.start}"
                print(f"{sdir} {tag}, check's frames kept: "
                      f"{score(late_dir, cache, args.truth, args.work / 'kept', keep=True)}")
                print(f"{sdir} {tag}: {score(late_dir, cache, args.truth, args.work / 'checked')}")


if __name__ == "__main__":
    main()

