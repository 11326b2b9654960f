"""A survey whose chainages are off: false trust and sky lost, with and without the doubt stated.

Copies a rendered survey with every frame's chainage moved by an error (its images linked, its
positions left out so that only the chainage places the frames), processes it with the given
chainage doubts and jitters (``docs/reconstruction.md``, section 18), and scores each mask file
against the ray-cast truth *at the chainages it states*: a mask published for chainage ``c`` must
bound the sky at ``c``. Errors (one per frame time, both cameras alike):

* ``none``: no error (the doubt's cost alone);
* ``biasX``: every frame ``X`` metres off (``bias3``, ``bias-3``);
* ``noiseX``: independent normal errors of ``X`` metres standard deviation;
* ``walkX``: a random walk of ``X`` metres per frame.

Doubts are ``D`` (each frame within ``D``) or ``D/J`` (within ``D``, and within ``J`` of the
others' common error); ``none`` processes with the survey's own statement (an exact chainage for
a synthetic survey). The segmentation cache of an earlier run is copied first, so only the
reconstruction runs.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_chainage_doubt.py DEMO_OUT --work /tmp/chain \\
        --errors none bias3 noise1.5 --doubts none 3 3/0.05
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import time
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from predisat.reconstruct.batch import process_survey
from predisat.reconstruct.evaluate import trust_counts
from predisat.reconstruct.params import PipelineParams
from predisat.synth.truth import true_masks
from predisat.synth.world import World
from predisat.track.map import TrackMap


def chainage_errors(kind: str, n: int, seed: int = 7) -> NDArray:
    """One error per frame time, metres (see the module doc)."""
    rng = np.random.default_rng(seed)
    if kind == "none":
        return np.zeros(n)
    for prefix, make in (
        ("bias", lambda x: np.full(n, x)),
        ("noise", lambda x: rng.normal(0.0, x, n)),
        ("walk", lambda x: np.cumsum(rng.normal(0.0, x, n))),
    ):
        if kind.startswith(prefix):
            return np.asarray(make(float(kind[len(prefix):])), float)
    raise SystemExit(f"unknown error {kind!r}: none, biasX, noiseX or walkX")


def moved_survey(src: Path, dst: Path, error_m: NDArray, times: NDArray) -> None:
    """``src`` copied to ``dst`` with each frame's chainage moved by its time's error."""
    if dst.exists():
        shutil.rmtree(dst)
    dst.mkdir(parents=True)
    for name in ("survey.yaml", "track.geojson"):
        shutil.copy(src / name, dst / name)
    for name in ("calib", "images"):
        (dst / name).symlink_to((src / name).resolve())
    man = pd.read_csv(src / "manifest.csv")
    man["chainage_m"] = man["chainage_m"] + error_m[times]
    man[["lat_deg", "lon_deg", "h_m"]] = np.nan  # the chainage alone places the frames
    man.to_csv(dst / "manifest.csv", index=False)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("world", type=Path, help="a `predisat demo --out` folder")
    ap.add_argument("--work", type=Path, required=True, help="a scratch folder")
    ap.add_argument("--errors", nargs="+", default=["none", "bias3"])
    ap.add_argument("--doubts", nargs="+", default=["none", "3"])
    args = ap.parse_args(argv)
    src, cache = args.world / "survey", args.world / "masks" / "cache"
    track = TrackMap.from_geojson(src / "track.geojson")
    world = World.load(args.world / "truth" / "world.npz", track)
    times = np.unique(pd.read_csv(src / "manifest.csv")["gps_s"].to_numpy(),
                      return_inverse=True)[1]  # fmt: skip
    print(f"{'error':>9} {'doubt':>8} {'false trust':>12} {'worst pos.':>10} "
          f"{'pos. > 0.1 %':>12} {'sky lost':>9} {'time':>6}")  # fmt: skip
    for kind in args.errors:
        survey = args.work / f"survey_{kind}"
        moved_survey(src, survey, chainage_errors(kind, int(times.max()) + 1), times)
        for doubt in args.doubts:
            out = args.work / f"out_{kind}_{doubt.replace('/', 'j')}"
            if out.exists():
                shutil.rmtree(out)
            if cache.exists():
                shutil.copytree(cache, out / "cache")
            p = PipelineParams()
            if doubt != "none":
                d, _, j = doubt.partition("/")
                p = dataclasses.replace(p, chainage_doubt_m=float(d),
                                        chainage_jitter_m=float(j) if j else None)  # fmt: skip
            t0 = time.perf_counter()
            masks = process_survey(survey, out, p, progress=False).masks
            took_s = time.perf_counter() - t0
            s = np.asarray(masks.chainage_m, float)
            trusted, good, visible = trust_counts(masks.effective_mask_deg,
                                                  true_masks(world, s).mask_el_deg)  # fmt: skip
            per_pos = (trusted - good).sum(axis=1) / np.maximum(trusted.sum(axis=1), 1)
            ft = 100.0 * (1.0 - good.sum() / max(int(trusted.sum()), 1))
            print(f"{kind:>9} {doubt:>8} {ft:11.5f}% {100 * per_pos.max():9.3f}% "
                  f"{int((per_pos > 1e-3).sum()):>5} of {s.size:<4} "
                  f"{100 * (1 - good.sum() / visible.sum()):8.2f}% {took_s:5.0f}s",
                  flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
