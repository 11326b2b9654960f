"""Contact sheet of synthetic frames across sky conditions and scenery, for ``docs/``.

Picks, from a synthetic survey written by ``predisat synth`` / ``predisat demo``, one frame per
scenery kind (open country, station, town, trees, cutting, rock walls, overbridge, tunnel mouth)
and cycles the sky conditions over them, so one small image shows what sky segmentation faces.

    python scripts/docs_contact_sheet.py demo_out --out docs/figures/contact_sheet.jpg
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from predisat.synth.generate import contact_sheet
from predisat.synth.world import World


def pick_frames(synth_dir: Path, per_kind: int = 2) -> dict[str, str]:
    """Frame ids covering every scenery kind (with the kind), alternating sides and skies."""
    world = World.load(synth_dir / "truth" / "world.npz")
    with open(synth_dir / "truth" / "frames.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    chainage = np.array([float(r["chainage_m"]) for r in rows])
    chosen: dict[str, str] = {}
    conditions = ("clear", "cloudy", "overcast")
    n_pick = 0
    for st in sorted(world.spec.stretches, key=lambda s: s.start_m):
        # frames inside the stretch (a tunnel: at its mouth, where the sky is still seen)
        lo, hi = (st.start_m - 20.0, st.start_m + 10.0) if st.kind == "tunnel" else (
            st.start_m, st.end_m)
        inside = [i for i in np.flatnonzero((chainage >= lo) & (chainage <= hi))
                  if rows[i]["frame_id"] not in chosen]
        if not inside:
            continue
        for _ in range(per_kind):
            want = conditions[n_pick % len(conditions)]
            side = ("left", "right")[n_pick % 2]
            best = [i for i in inside if rows[i]["sky"] == want and rows[i]["side"] == side]
            pool = best or [i for i in inside if rows[i]["side"] == side] or inside
            i = pool[len(pool) // 2]
            inside.remove(i)
            chosen[rows[i]["frame_id"]] = st.kind.replace("_", " ")
            n_pick += 1
            if not inside:
                break
    return chosen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("synth_dir", type=Path, help="output folder of predisat synth / demo")
    ap.add_argument("--out", type=Path, default=Path("docs/figures/contact_sheet.jpg"))
    ap.add_argument("--per-kind", type=int, default=2, help="frames per scenery kind")
    ap.add_argument("--tile-width", type=int, default=300, help="tile width, px")
    args = ap.parse_args()
    frames = pick_frames(args.synth_dir, args.per_kind)
    out = contact_sheet(
        args.synth_dir / "survey", args.out, frames=list(frames), columns=4,
        tile_width_px=args.tile_width, notes=frames,
    )
    print(f"{out}: {len(frames)} frames, {out.stat().st_size / 1024:.0f} kB")


if __name__ == "__main__":
    main()
