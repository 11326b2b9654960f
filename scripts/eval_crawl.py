"""A crawl captured on time: what the stop merge (``predisat.reconstruct.stops``) costs in sky.

A camera triggered on time at walking pace (or a video) gives frames a few decimetres apart.
The stop merge (docs/reconstruction.md, section 24) makes the frames of one camera within
``gap_m`` of each other one view, whose position doubt holds all of them: chained over a whole
crawl, that view's doubt spanned the crawl and every position lost all its sky. This script
measures, with the rig's *ideal* (ray-cast) sky masks through the reconstruction, no
segmentation: the 10 m frames of a distance-triggered survey, and the crawl merged with each
``--merge GAP:SPAN`` (``0:0`` counts its frames alone; a span over the crawl's length, e.g.
``0.5:1000``, merges it whole as the chaining before the cut did, with its 0.5 m step). Sky lost
across / along the track and false trust against the ray-cast truth at the 10 m positions of
``[FROM, TO]``.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_crawl.py --from-m 7300 --to-m 7320 \\
        --step-m 0.1 --pad-m 10 --merge 0:0 0.2:0.5 0.5:1000

The world is :func:`eval_rigs.held_out_spec` of ``--seed`` over km 7.05-8.05 (the rig
evaluation's), the rig the side fisheye pair at ``--scale``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from eval_rigs import _counts, held_out_spec

from predisat.camera.rigs import Rig
from predisat.masks.margins import sector_of
from predisat.reconstruct.carving import FrameView, Reconstructor
from predisat.reconstruct.params import PipelineParams
from predisat.reconstruct.stops import merge_stop_frames
from predisat.synth.render import Casters
from predisat.synth.truth import ideal_frames, true_masks
from predisat.synth.world import World
from predisat.track.map import demo_track


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--from-m", type=float, default=7300.0)
    ap.add_argument("--to-m", type=float, default=7320.0)
    ap.add_argument("--step-m", type=float, default=0.1, help="the crawl's frame spacing")
    ap.add_argument("--pad-m", type=float, default=10.0,
                    help="the crawl runs this far beyond [FROM, TO] on each side")
    ap.add_argument("--merge", nargs="+", default=["0:0", "0.2:0.5", "0.5:1000"],
                    metavar="GAP:SPAN", help="stop_gap_m:stop_span_m pairs to merge the crawl with")
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--scale", type=float, default=0.5)
    a = ap.parse_args(argv)
    lo, hi, pad = a.from_m, a.to_m, a.pad_m
    track = demo_track()
    world = World.build(track, held_out_spec(7050.0, 8050.0, a.seed), a.seed)
    s = np.arange(lo, hi + 1e-9, 10.0)
    tm = true_masks(world, s, 4.0, caster=Casters.for_world(world, "open3d").lband)
    sector = sector_of(tm.az_deg[None, :], tm.heading_deg[:, None])
    rig = Rig.preset("side-fisheye").scaled(a.scale)
    thin = PipelineParams().thin_deg

    def frames_at(ch: np.ndarray) -> list[FrameView]:
        out: list[FrameView] = []
        for pos, cam, mount in rig.cameras:
            out += ideal_frames(world, ch, cam, {pos: mount}, thin_deg=thin)
        return out

    t0 = time.perf_counter()
    base = frames_at(np.arange(lo - 150.0, hi + 150.0 + 1e-9, 10.0))
    far = np.concatenate([np.arange(lo - 150.0, lo - pad, 10.0),
                          np.arange(hi + pad + 10.0, hi + 151.0, 10.0)])  # fmt: skip
    crawl = frames_at(np.arange(lo - pad, hi + pad + 1e-9, a.step_m)) + frames_at(far)
    print(f"ray-cast {len(base)} + {len(crawl)} frames in {time.perf_counter() - t0:.0f} s",
          flush=True)  # fmt: skip

    def run(name: str, frames: list[FrameView]) -> None:
        rec = Reconstructor().run(frames, s, world.track)
        c = _counts(rec.mask_el_deg.astype(float), tm.mask_el_deg, sector)
        print(f"{name:26s} {len(frames):6d} views  sky lost across {100 * c['sky_lost_cross']:6.2f}"
              f" %, along {100 * c['sky_lost_along']:6.2f} %, all {100 * c['sky_lost_all']:6.2f} %"
              f"; false trust {100 * c['false_trust_all']:.4f} %", flush=True)  # fmt: skip

    run("frames every 10 m", base)
    for pair in a.merge:
        gap, span = (float(x) for x in pair.split(":"))
        run(f"crawl, gap {gap:g}, span {span:g} m", merge_stop_frames(crawl, gap, span))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
