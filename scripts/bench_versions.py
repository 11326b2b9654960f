"""Throughput of this checkout's pipeline against a baseline checkout, in one process.

Usage::

    git worktree add /tmp/base <commit>      # the code to compare against
    python scripts/bench_versions.py SURVEY_DIR --baseline /tmp/base [--repeat 5]
        [--pipeline-repeat 3] [--frames N] [--json bench_versions.json]

Both versions of the ``predisat`` package are imported into this one process (the baseline's
modules swapped into ``sys.modules`` while it runs), and timed on the same decoded frames,
interleaved (the order alternates every repeat), best of ``--repeat``: on a shared machine the
best time is the least disturbed one. One thread: OpenCV, BLAS, OpenMP and numba are pinned
before numpy loads.

Stages, per frame of the survey:

* ``decode``: ``cv2.imread`` of every frame (the floor of issue 3);
* ``segment``: ``segment_sky`` with the default options on the decoded frames;
* ``reconstruct``: ``Reconstructor.run`` on the survey's 1000 m chunks from the sky masks and
  confidences (the pipeline's windows, without the cache files);
* ``pipeline``: the whole ``process_survey`` (one worker, a fresh output folder each time), per
  stage as it reports them.

Every output is compared bit for bit between the two versions (sky masks, skylines,
confidences, valid masks, the chunks' masks, sources and descriptors, and ``masks.parquet``);
the script exits with an error when any differs.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
             "OPENCV_FOR_THREADS_NUM"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Iterator  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from pathlib import Path  # noqa: E402
from types import ModuleType  # noqa: E402
from typing import Any  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

_NAMES = ("segmentation", "pipeline", "reconstruct", "survey", "maskio")


def _is_ours(name: str) -> bool:
    return name == "predisat" or name.startswith("predisat.")


class Version:
    """One importable copy of the package, kept out of ``sys.modules`` unless in use."""

    def __init__(self, label: str, root: Path | None) -> None:
        self.label = label
        self.modules: dict[str, ModuleType] = {}
        saved = {k: v for k, v in sys.modules.items() if _is_ours(k)}
        for k in saved:
            del sys.modules[k]
        if root is not None:
            sys.path.insert(0, str(root))
        importlib.invalidate_caches()
        try:
            for name in _NAMES:
                importlib.import_module(f"predisat.{name}")
            self.root = Path(sys.modules["predisat"].__file__ or "").parent
        finally:
            if root is not None:
                sys.path.remove(str(root))
            self.modules = {k: v for k, v in sys.modules.items() if _is_ours(k)}
            for k in self.modules:
                del sys.modules[k]
            sys.modules.update(saved)

    @contextmanager
    def active(self) -> Iterator[dict[str, ModuleType]]:
        """Make this version the ``predisat`` that lazy imports inside its functions see."""
        saved = {k: v for k, v in sys.modules.items() if _is_ours(k)}
        for k in saved:
            del sys.modules[k]
        sys.modules.update(self.modules)
        try:
            yield {n: self.modules[f"predisat.{n}"] for n in _NAMES}
        finally:
            self.modules = {k: v for k, v in sys.modules.items() if _is_ours(k)}
            for k in self.modules:
                del sys.modules[k]
            sys.modules.update(saved)


def _same(a: Any, b: Any) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.kind == "f":  # NaN-aware, and -0.0 is not 0.0
        return bool(np.array_equal(a, b, equal_nan=True)
                    and np.array_equal(np.signbit(a), np.signbit(b)))  # fmt: skip
    return bool(np.array_equal(a, b))


def _interleaved(
    versions: list[Version], repeat: int, run: Callable[[str, dict[str, ModuleType]], Any]
) -> tuple[dict[str, float], dict[str, Any]]:
    """Best wall time of ``run`` per version over ``repeat`` interleaved rounds, and each
    version's last result."""
    best = {v.label: np.inf for v in versions}
    out: dict[str, Any] = {}
    for r in range(repeat):
        for v in versions if r % 2 == 0 else versions[::-1]:
            with v.active() as mods:
                t0 = time.perf_counter()
                out[v.label] = run(v.label, mods)
                best[v.label] = min(best[v.label], time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("survey", type=Path)
    ap.add_argument("--baseline", type=Path, required=True,
                    help="folder holding the baseline's predisat/ (a git worktree)")
    ap.add_argument("--repeat", type=int, default=5, help="rounds for segment and reconstruct")
    ap.add_argument("--pipeline-repeat", type=int, default=3,
                    help="rounds of process_survey (0: skip it)")
    ap.add_argument("--frames", type=int, default=None, help="segment only the first N frames")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    if not (args.baseline / "predisat" / "__init__.py").is_file():
        raise SystemExit(f"{args.baseline} holds no predisat package")

    versions = [Version("baseline", args.baseline.resolve()), Version("current", None)]
    for v in versions:
        print(f"{v.label:<9s}: {v.root}")
    if versions[0].root == versions[1].root:
        raise SystemExit("the baseline is this checkout")

    surveys = {}
    for v in versions:  # each version reads the survey (track, cameras) with its own classes
        with v.active() as mods:
            surveys[v.label] = mods["survey"].Survey.load(
                args.survey, check_images=False, on_error="skip"
            )
    survey = surveys["current"]
    fr = survey.frames
    n = len(fr)
    paths = [str(survey.image_path(i)) for i in range(n)]
    t0 = time.perf_counter()
    images = [cv2.imread(p, cv2.IMREAD_COLOR) for p in paths]
    decode_s = time.perf_counter() - t0
    for _ in range(args.repeat - 1):
        t0 = time.perf_counter()
        for p in paths:
            cv2.imread(p, cv2.IMREAD_COLOR)
        decode_s = min(decode_s, time.perf_counter() - t0)
    n_seg = n if args.frames is None else min(n, args.frames)
    results: dict[str, Any] = {"decode_ms": 1e3 * decode_s / n}
    identical = True

    # warm-up: models, numba caches, first calls
    for v in versions:
        with v.active() as mods:
            mods["segmentation"].segment_sky(images[0])

    def segment(label: str, mods: dict[str, ModuleType]) -> list[Any]:
        seg = mods["segmentation"].segment_sky
        return [seg(img) for img in images[:n_seg]]

    best, segs = _interleaved(versions, args.repeat, segment)
    same_seg = all(
        _same(getattr(a, f), getattr(b, f))
        for a, b in zip(segs["baseline"], segs["current"], strict=True)
        for f in ("sky_mask", "skyline_row", "confidence", "valid_mask")
    )
    identical &= same_seg
    results["segment_ms"] = {k: 1e3 * t / n_seg for k, t in best.items()}
    results["segment_identical"] = same_seg
    masks = [(s.sky_mask, s.confidence.astype(np.float32)) for s in segs["current"]]
    del segs
    if n_seg < n:  # the reconstruction needs every frame
        with versions[1].active() as mods:
            masks += [(s.sky_mask, s.confidence.astype(np.float32))
                      for s in (mods["segmentation"].segment_sky(img) for img in images[n_seg:])]

    # reconstruction on the pipeline's chunks
    track = survey.track
    if track is None:
        raise SystemExit(f"survey {args.survey} names no track file")
    ch = np.round(np.asarray(fr.chainage_m, float), 3)
    ok = np.isfinite(ch)
    positions = np.unique(ch[ok])
    s_ok = ch[ok]
    idx_ok = np.flatnonzero(ok)
    ant = np.asarray(track.enu_at(s_ok), float)
    ant += float(survey.antenna_height_m) * np.asarray(track.up_at(s_ok), float)
    heading = np.asarray(track.heading_at(s_ok), float)

    def reconstruct(label: str, mods: dict[str, ModuleType]) -> list[Any]:
        rc = mods["reconstruct"]
        sv = surveys[label]
        rec = rc.Reconstructor(rc.ReconstructionParams())
        views = []
        for k, i in enumerate(idx_ok):
            cam = sv.cameras[str(fr.side[i])]
            views.append(rc.FrameView(
                float(ch[i]), masks[i][0], cam.camera, cam.mount, ant[k], float(heading[k]),
                bool(survey.reverse), masks[i][1], str(fr.frame_id[i]),
            ))  # fmt: skip
        out = []
        chunk = np.floor(positions / 1000.0)
        for kk in np.unique(chunk):
            s = positions[chunk == kk]
            lo, hi = s.min() - rec.params.overlap_m, s.max() + rec.params.overlap_m
            out.append(rec.run([f for f in views if lo <= f.chainage_m <= hi], s, sv.track))
        return out

    best, recs = _interleaved(versions, args.repeat, reconstruct)
    same_rec = all(
        _same(getattr(a, f), getattr(b, f))
        for a, b in zip(recs["baseline"], recs["current"], strict=True)
        for f in ("mask_el_deg", "source", "grid_el_deg", "far_el_deg", "overhead_m")
    ) and all(
        _same(a.descriptors[d], b.descriptors[d])
        for a, b in zip(recs["baseline"], recs["current"], strict=True)
        for d in a.descriptors
    )
    identical &= same_rec
    results["reconstruct_ms"] = {k: 1e3 * t / n for k, t in best.items()}
    results["reconstruct_identical"] = same_rec
    del recs

    # the whole pipeline
    stage_best: dict[str, dict[str, float]] = {v.label: {} for v in versions}
    arrays: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.pipeline_repeat):
            for v in versions if r % 2 == 0 else versions[::-1]:
                with v.active() as mods:
                    out_dir = Path(tmp) / f"{v.label}{r}"
                    res = mods["pipeline"].process_survey(
                        args.survey, out_dir, workers=1, progress=False
                    )
                    times = {**res.timings_s, "total": res.elapsed_s}
                    for stage, s in times.items():
                        prev = stage_best[v.label].get(stage, np.inf)
                        stage_best[v.label][stage] = min(prev, s)
                    m = mods["maskio"].read_masks(out_dir / "masks.parquet")
                    arrays[v.label] = [m.chainage_m, m.mask_el_deg, m.source, m.margin_deg,
                                       m.lat_deg, m.lon_deg, m.h_m, m.heading_deg,
                                       *(m.descriptors[d] for d in sorted(m.descriptors))]
    same_pipe = not arrays or (
        len(arrays["baseline"]) == len(arrays["current"])
        and all(_same(a, b) for a, b in zip(arrays["baseline"], arrays["current"], strict=True))
    )
    identical &= same_pipe
    results["pipeline_ms"] = {k: {s: 1e3 * t / n for s, t in v.items()}
                              for k, v in stage_best.items()}  # fmt: skip
    results["pipeline_identical"] = same_pipe

    def line(name: str, old: float, new: float, same: bool | None = None) -> None:
        tag = "" if same is None else ("  identical" if same else "  DIFFERENT")
        print(f"{name:<22s}{old:9.2f}{new:9.2f}{old / new:8.2f}x{tag}")

    print(f"\n{n} frames ({n_seg} segmented in the segment stage), best of {args.repeat} "
          f"(pipeline: {args.pipeline_repeat}), ms per frame, one thread")  # fmt: skip
    print(f"{'stage':<22s}{'baseline':>9s}{'current':>9s}{'ratio':>9s}")
    print(f"{'decode (floor)':<22s}{results['decode_ms']:9.2f}")
    seg_ms, rec_ms = results["segment_ms"], results["reconstruct_ms"]
    line("segment_sky", seg_ms["baseline"], seg_ms["current"], same_seg)
    line("reconstruct (chunks)", rec_ms["baseline"], rec_ms["current"], same_rec)
    for stage in stage_best["current"]:
        line(f"pipeline {stage}", stage_best["baseline"][stage] * 1e3 / n,
             stage_best["current"][stage] * 1e3 / n,
             same_pipe if stage == "total" else None)  # fmt: skip
    for v in versions:
        if stage_best[v.label]:
            ratio = stage_best[v.label]["total"] / decode_s
            print(f"{v.label}: pipeline / decode = {ratio:.1f}x")
    results["baseline"] = str(versions[0].root)
    results["survey"] = str(args.survey)
    results["frames"] = n
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))
    if not identical:
        raise SystemExit("the current code's outputs differ from the baseline's")


if __name__ == "__main__":
    main()
