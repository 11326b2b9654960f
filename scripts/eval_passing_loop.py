"""A train on a passing loop, located on the main track: the masks it takes, with and without the
loop's masks merged worst-case (docs/mask-format.md, "Passing loops and parallel tracks").

Builds a synthetic world along the demo line (``WorldSpec.mixed``, one seed per run), lays a
loop track ``--offset`` metres beside the main track over the whole stretch (tapered over 60 m
at its switches) on each side in turn, and ray-casts the true masks on both tracks every 2.5 m.
Each track's masks are made every 10 m as the pipeline makes them, safe over their cell: each
position's mask is the worst of the true masks over the cell's places (no segmentation error:
the route's effect alone). The train stands at loop places half-way between those samples
(``1.25 + 2.5 k`` m of the loop's chainage), each with its own true mask. Looked up at its foot
point on the main track, as the locator locates it, the script scores:

* ``main``: the main track's masks;
* ``merged``: the same, merged worst-case with the loop's masks
  (:func:`predisat.masks.merge.merge_worst_case`);
* ``loop's own``: the loop's masks on the loop's map (the train located on the track it is on,
  for reference: what sampling the truth every 2.5 m leaves);

false trust = trusted directions truly blocked at the loop place / trusted directions (0.5 deg
elevation grid). Loop places within ``--gauge`` metres of an obstacle on either side (a real
track keeps its structure gauge: the world was built for the main track only) and covered
places are left out and counted. As the locator does over its predicted interval, the masks
are taken worst over ``+- --window`` metres about the place's chainage. The cost of the merge
is the main track's sky lost: truly visible directions at the main track's samples that its
masks trust and the merged masks no longer do.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_passing_loop.py --seeds 41 42 --offset 4.5
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from predisat.masks.maskset import MaskSet
from predisat.masks.merge import merge_worst_case
from predisat.reconstruct.evaluate import trust_counts
from predisat.synth.truth import true_masks
from predisat.synth.world import World, WorldSpec
from predisat.track import TrackMap, demo_track

ANTENNA_M = 4.0
AZ_STEP_DEG = 0.5


def loop_track(main: TrackMap, lo_m: float, hi_m: float, offset_m: float,
               taper_m: float = 60.0) -> TrackMap:
    """A track ``offset_m`` beside ``main`` (positive: left of increasing chainage) between
    ``lo_m`` and ``hi_m``, joining it over ``taper_m`` at each end, in the main track's frame."""
    s = np.arange(lo_m, hi_m + 1e-9, 2.0)
    d = offset_m * np.clip(np.minimum(s - lo_m, hi_m - s) / taper_m, 0.0, 1.0)
    enu = np.asarray(main.enu_at(s), float)
    hd = np.radians(np.asarray(main.heading_at(s), float))
    left = np.column_stack([-np.cos(hd), np.sin(hd), np.zeros_like(hd)])
    lat, lon, h = main.frame.to_geodetic(enu + d[:, None] * left)
    return TrackMap(f"loop {offset_m:+g} m", np.asarray(lat), np.asarray(lon), np.asarray(h),
                    main.frame, tolerance_m=0.05, vertical_tolerance_m=0.05)


def cell_masks(track: TrackMap, fine_m: np.ndarray, truth_el: np.ndarray) -> MaskSet:
    """Masks every 10 m (every 4th place of the 2.5 m grid ``fine_m``, from its third), each
    the worst of the true masks over its cell's places (both edges included)."""
    idx = np.arange(2, fine_m.size - 2, 4)
    worst = np.max(np.stack([truth_el[idx + d] for d in (-2, -1, 0, 1, 2)]), axis=0)
    return MaskSet.from_track(track, fine_m[idx], worst.astype(np.float32),
                              provenance={"track": track.name})


def score(masks: MaskSet, at_m: np.ndarray, truth_el: np.ndarray, window_m: float
          ) -> tuple[int, int]:
    """Trusted directions and those truly blocked, the masks taken worst over ``+-window_m``
    about each place's chainage as the locator takes them over its prediction."""
    worst = masks.worst_case(at_m - window_m, at_m + window_m, clip=True)
    k = masks.bin_index(np.arange(truth_el.shape[1]) * AZ_STEP_DEG)
    trusted, trusted_los, _ = trust_counts(worst[:, k], truth_el)
    return int(trusted.sum()), int((trusted - trusted_los).sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[41])
    ap.add_argument("--offset", type=float, default=4.5, help="loop beside the track, metres")
    ap.add_argument("--from-m", type=float, default=100.0)
    ap.add_argument("--to-m", type=float, default=1900.0)
    ap.add_argument("--window", type=float, default=5.0,
                    help="masks taken worst over +- this about the place (the locator takes "
                    "them over its prediction, tens of metres), metres")
    ap.add_argument("--gauge", type=float, default=2.0,
                    help="loop places nearer an obstacle than this are left out, metres")
    a = ap.parse_args()
    main_track = demo_track()
    lo, hi = a.from_m, a.to_m
    totals = {"main": [0, 0], "merged": [0, 0], "loop's own": [0, 0]}
    lost = [0, 0]
    for seed in a.seeds:
        t0 = time.time()
        world = World.build(main_track, WorldSpec.mixed(0.0, 2000.0, seed), seed)
        fine_a = np.arange(lo - 5.0, hi + 5.0 + 1e-9, 2.5)
        truth_a = true_masks(world, fine_a, ANTENNA_M, AZ_STEP_DEG)
        m_a = cell_masks(main_track, fine_a, truth_a.mask_el_deg)
        for side in (+1.0, -1.0):
            loop = loop_track(main_track, lo, hi, side * a.offset)
            w_b = World(loop, world.frame, world.spec, seed, world.vertices_m, world.faces,
                        world.face_material)
            fine_b = np.arange(0.0, loop.length_m, 2.5)
            m_b = cell_masks(loop, fine_b, true_masks(w_b, fine_b, ANTENNA_M, AZ_STEP_DEG)
                             .mask_el_deg)
            places = fine_b[(fine_b >= 5.0) & (fine_b < loop.length_m - 5.0)] + 1.25
            truth_b = true_masks(w_b, places, ANTENNA_M, AZ_STEP_DEG)
            merged = merge_worst_case(m_a, [m_b], main_track, labels=[loop.name]).masks
            near = np.nanmin(np.where(np.isnan(truth_b.obstacle_distance_m), np.inf,
                                      truth_b.obstacle_distance_m), axis=1)
            ok = ~truth_b.covered & (near >= a.gauge)
            lat, lon, _ = loop.position_at(places[ok])
            at = np.asarray(main_track.project(lat, lon).chainage_m)
            inside = (at >= m_a.cell_bounds_m[0]) & (at <= m_a.cell_bounds_m[-1])
            own = (places[ok] >= m_b.cell_bounds_m[0]) & (places[ok] <= m_b.cell_bounds_m[-1])
            row = f"seed {seed} {'left' if side > 0 else 'right'}: {int(ok.sum())} loop places " \
                  f"({int((~ok).sum())} within the gauge or covered left out)"
            for name, m, where, keep in (("main", m_a, at, inside), ("merged", merged, at, inside),
                                         ("loop's own", m_b, places[ok], own)):
                n_t, n_ft = score(m, where[keep], truth_b.mask_el_deg[ok][keep], a.window)
                totals[name][0] += n_t
                totals[name][1] += n_ft
                row += f"; {name}: false trust {100.0 * n_ft / max(n_t, 1):.3f} %"
            # the price on the main track: its visible sky the merged masks no longer trust
            i = np.asarray(m_a.position_index(fine_a)[0])
            _, before, vis = trust_counts(m_a.effective_mask_deg[i], truth_a.mask_el_deg)
            _, after, _ = trust_counts(merged.effective_mask_deg[i], truth_a.mask_el_deg)
            lost[0] += int(vis.sum())
            lost[1] += int(before.sum() - after.sum())
            row += ("; main track's sky lost to the merge "
                    f"{100.0 * (before.sum() - after.sum()) / vis.sum():.1f} %")
            print(row, flush=True)
        print(f"  seed {seed}: {time.time() - t0:.0f} s", flush=True)
    for name, (n_t, n_ft) in totals.items():
        print(f"all: {name} masks at loop places: false trust {100.0 * n_ft / max(n_t, 1):.4f} % "
              f"({n_ft} of {n_t} trusted directions)")
    share = 100.0 * lost[1] / max(lost[0], 1)
    print(f"all: main track's visible sky lost to the merge {share:.1f} %")


if __name__ == "__main__":
    main()
