"""Figure of docs/rigs.md: the thin-structure policy near the zenith of a panorama (issue 32).

Ray-casts the ideal sky mask of the ``360`` rig's panorama (half resolution) at one chainage
of a held-out world of ``scripts/eval_rigs.py`` and draws its top rows twice: the frame
policy in pixels (:func:`predisat.sky.morphology.remove_thin_obstacles`, what panoramas got
before) and the policy on the sphere (:func:`predisat.sky.panorama.remove_thin_obstacles_equirect`).
Grey: obstacle for both masks; red: thin-material pixels (wires, cantilevers) kept as obstacles;
green: pixels the policy made thin; blue: sky.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/pano_thin_figure.py \\
        --world /tmp/eval_rigs_full/360_s11/synth/truth/world.npz --chainage-m 7000 \\
        --out docs/figures/pano_thin_policy.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from predisat.camera.rigs import Rig
from predisat.reconstruct.params import PipelineParams
from predisat.sky.morphology import remove_thin_obstacles
from predisat.sky.panorama import remove_thin_obstacles_equirect
from predisat.synth.truth import ideal_frames
from predisat.synth.world import World


def _colour(raw_sky: np.ndarray, after: np.ndarray, lband_sky: np.ndarray) -> np.ndarray:
    img = np.zeros((*raw_sky.shape, 3))
    img[after] = (0.58, 0.78, 1.0)
    img[~lband_sky] = (0.25, 0.25, 0.25)
    img[~after & lband_sky] = (0.9, 0.0, 0.0)
    img[after & ~raw_sky] = (0.0, 0.75, 0.0)
    return img


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--world", type=Path, default=Path("/tmp/eval_rigs_full/360_s11/synth/truth/world.npz")
    )
    ap.add_argument("--chainage-m", type=float, default=7000.0)
    ap.add_argument("--rows", type=int, default=60, help="top rows drawn")
    ap.add_argument("--out", type=Path, default=Path("docs/figures/pano_thin_policy.png"))
    args = ap.parse_args(argv)
    world = World.load(args.world)
    ((pos, cam, mount),) = Rig.preset("360").scaled(0.5).cameras
    s = np.array([args.chainage_m])
    thin_px = PipelineParams().thin_px(cam)
    new = ideal_frames(world, s, cam, {pos: mount}, thin_deg=PipelineParams().thin_deg)[0]
    lband = ideal_frames(world, s, cam, {pos: mount})[0].sky_mask  # thin materials as sky
    assert new.thin_mask is not None
    raw = new.sky_mask & ~new.thin_mask  # every face a camera sees
    old = remove_thin_obstacles(raw, thin_px)
    sphere = remove_thin_obstacles_equirect(raw, thin_px)  # what ideal_frames now applies
    rows = slice(0, args.rows)
    fig, axes = plt.subplots(2, 1, figsize=(12, 2.6), constrained_layout=True)
    for ax, after, title in ((axes[0], old, "frame policy in pixels (before)"),
                             (axes[1], sphere, "policy on the sphere (now)")):  # fmt: skip
        n_kept = int((~after & lband)[rows].sum())
        ax.imshow(_colour(raw, after, lband)[rows], aspect="auto", interpolation="nearest",
                  extent=(-180, 180, 90 - args.rows * 0.5, 90))  # fmt: skip
        ax.set_title(f"{title}: {n_kept} thin-material pixels kept as obstacles", fontsize=9)
        ax.set_ylabel("elevation (deg)", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[1].set_xlabel("azimuth from ahead (deg)", fontsize=8)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
