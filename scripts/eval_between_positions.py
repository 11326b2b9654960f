"""False trust of a mask file between its survey positions, against the ray-cast truth.

A train stands anywhere along the track, not only at the survey positions (every 10 m) where
the masks and their truth are computed. This casts the true masks of a rendered world at the
positions moved by ``--offset-m`` along the track (5 m: the cell edge, half-way to the next
position) and compares each with the mask of the cell that holds it
(``docs/reconstruction.md``, section 12). Figures, per mask file:

* false trust: the share of trusted elevation-degrees (``90 - mask`` summed over bins) that
  the truth at the offset position hides (``truth - mask`` where positive);
* the share of bins hidden by more than 1 and 5 deg, and the positions with any bin over 1;
* the same for the maximum of the cell's mask and the next one's (what a user taking the
  worst of the two cells either side would get), and the control: the mask against the
  truth at its own position;
* for reference, the world's true masks at the positions with the campaign's 1 deg margin
  (a perfect survey sampled every 10 m).

``--swept`` also casts the truth 2.5 m either side of each position and scores every mask
file against the truth at the positions and against the truth swept over each cell (the
maximum of the five casts: centre, +-2.5 m and both edges; positions 1 to n-2): sky lost and
false trust as shares of the solid angle (directions weighted by cos(elevation)),
``docs/reconstruction.md`` section 12.

Usage::

    .venv/bin/python scripts/eval_between_positions.py DEMO_OUT [--masks M.parquet ...]
        [--offset-m 5] [--cache truth_off5.npz]

``DEMO_OUT`` is a ``predisat demo --out`` folder or a world folder of ``scripts/eval_rigs.py``
/ ``scripts/eval_ood_world.py``; the masks default to the folder's own.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from numpy.typing import NDArray


def _folders(world: Path) -> tuple[Path, Path]:
    truth = world / "truth"
    if not (truth / "world.npz").exists():
        truth = world / "synth" / "truth"
    masks = world / "masks" / "masks.parquet"
    return truth, masks if masks.exists() else world / "proc" / "masks.parquet"


def figures(mask_el_deg: NDArray, truth_el_deg: NDArray) -> dict[str, float]:
    """False-trust figures of masks (n, n_az) against a truth of the same shape."""
    m = np.asarray(mask_el_deg, float)
    trusted = np.clip(90.0 - m, 0.0, None)
    hidden = np.minimum(np.clip(np.minimum(truth_el_deg, 90.0) - m, 0.0, None), trusted)
    return {
        "false_trust_pct": float(100.0 * hidden.sum() / max(trusted.sum(), 1e-300)),
        "bins_over_1deg_pct": float(100.0 * np.mean(hidden > 1.0)),
        "bins_over_5deg_pct": float(100.0 * np.mean(hidden > 5.0)),
        "positions_over_1deg": float(np.any(hidden > 1.0, axis=1).sum()),
        "positions": float(len(m)),
    }


_EL_DEG = np.arange(0.25, 90.0, 0.5)


def solid_angle_shares(mask_el_deg: NDArray, truth_el_deg: NDArray) -> tuple[float, float]:
    """Sky lost (visible, not trusted) and false trust (trusted, hidden), percent of the
    visible and of the trusted solid angle, masks and truth (n, n_az) in degrees."""
    m = np.clip(np.asarray(mask_el_deg, float), 0.0, 90.0)[..., None]
    t = np.clip(np.asarray(truth_el_deg, float), 0.0, 90.0)[..., None]
    w = np.cos(np.radians(_EL_DEG))
    vis, tru = _EL_DEG > t, _EL_DEG > m
    lost = float(((vis & ~tru) * w).sum() / max(float((vis * w).sum()), 1e-300))
    false = float(((tru & ~vis) * w).sum() / max(float((tru * w).sum()), 1e-300))
    return 100.0 * lost, 100.0 * false


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("world", type=Path, help="a rendered world folder (see the module doc)")
    ap.add_argument("--masks", type=Path, nargs="+", help="mask files (default the world's)")
    ap.add_argument("--offset-m", type=float, default=5.0, help="along-track offset, metres")
    ap.add_argument("--cache", type=Path, help="an .npz to keep the offset truth in")
    ap.add_argument("--swept", action="store_true",
                    help="also score against the truth swept over each cell (see above)")
    args = ap.parse_args(argv)
    from predisat.masks.fileformat import read_masks
    from predisat.masks.truth import TrueMasks
    from predisat.synth.truth import true_masks
    from predisat.synth.world import World
    from predisat.track.map import demo_track

    truth_dir, own = _folders(args.world)
    tm = TrueMasks.load(truth_dir / "true_masks.npz")
    s = np.asarray(tm.chainage_m, float)
    if args.swept and (args.offset_m != 5.0 or len(s) < 3):
        raise SystemExit("--swept needs --offset-m 5 (the cell edges of 10 m cells) and at "
                         "least 3 positions")  # fmt: skip
    cached = dict(np.load(args.cache)) if args.cache is not None and args.cache.exists() else {}
    world = None

    def cast(key: str, chainage_m: NDArray) -> NDArray:
        nonlocal world
        if key not in cached:
            world = world or World.load(truth_dir / "world.npz", demo_track())
            cached[key] = true_masks(world, chainage_m).mask_el_deg
            if args.cache is not None:
                np.savez(args.cache, **cached)
        return cached[key]

    moved = cast("el", s[:-1] + args.offset_m)
    print(f"{args.world}: truth at {len(s) - 1} positions moved by {args.offset_m:+.1f} m")
    ref = figures(np.asarray(tm.mask_el_deg, float)[:-1] + 1.0, moved)
    print(f"  true masks + 1 deg       false trust {ref['false_trust_pct']:.4f} % of trusted "
          f"el-deg; positions > 1 deg {ref['positions_over_1deg']:.0f} of {ref['positions']:.0f}")
    for path in args.masks or [own]:
        ms = read_masks(path)
        if not np.allclose(ms.chainage_m, s):
            raise SystemExit(f"{path}: positions differ from the truth's; give the world's masks")
        p = np.asarray(ms.mask_el_deg, float)
        rows = {
            "cell": figures(p[:-1], moved),
            "max(cell, next)": figures(np.maximum(p[:-1], p[1:]), moved),
            "control (own position)": figures(p[:-1], tm.mask_el_deg[:-1]),
        }
        print(path)
        if args.swept:
            i = np.arange(1, len(s) - 1)
            swept = np.max(np.stack([
                tm.mask_el_deg[i], cast("inner_minus_2.5", s[i] - 2.5),
                cast("inner_plus_2.5", s[i] + 2.5),
                moved[i], moved[i - 1],
            ]), axis=0)  # fmt: skip
            for tname, truth in (("at the positions", tm.mask_el_deg[i]),
                                 ("swept over the cell", swept)):  # fmt: skip
                lost, false = solid_angle_shares(p[i], truth)
                print(f"  truth {tname:20s} sky lost {lost:.2f} %, false trust {false:.4f} % "
                      "(solid angle)")  # fmt: skip
        for name, f in rows.items():
            print(f"  {name:24s} false trust {f['false_trust_pct']:.4f} % of trusted el-deg; "
                  f"bins > 1 deg {f['bins_over_1deg_pct']:.3f} %, > 5 deg "
                  f"{f['bins_over_5deg_pct']:.3f} %; positions > 1 deg "
                  f"{f['positions_over_1deg']:.0f} of {f['positions']:.0f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
