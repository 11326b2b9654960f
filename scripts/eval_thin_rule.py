"""The physical thin-structure rule near catenary masts, ideal labels (issue 30, item 5;
``docs/reconstruction.md``, section 8).

A straight 700 m open-country world with catenary (masts every ~60 m, cantilever arm and strut
0.06 m, wires), a 320 x 240 side fisheye every 10 m, masks every metre over 100 m (two mast
spans). Prints false trust (trusted directions truly blocked / trusted, no margin) and sky lost
for the masks before (every thin-material face sky at any width and distance, no rule) and
after (the pipeline's 0.7 deg policy with the Fresnel rule), each against the truth before
(thin structures never block) and after (they block where the rule says so)::

    PYTHONPATH=. .venv/bin/python scripts/eval_thin_rule.py
"""

from __future__ import annotations

import numpy as np

from predisat.camera.models import CameraModel
from predisat.masks.margins import EL_STEP_DEG
from predisat.reconstruct.carving import ReconstructionParams, Reconstructor
from predisat.reconstruct.evaluate import trust_counts
from predisat.synth.raycast import make_caster
from predisat.synth.truth import ideal_frames, true_masks
from predisat.synth.world import Stretch, World, WorldSpec
from tests.predisat.synth.test_world import straight_track


def main() -> None:
    track = straight_track(700.0, 30.0)
    world = World.build(track, WorldSpec((Stretch("open", 0.0, 700.0),), True, False), seed=3)
    cam = CameraModel.fisheye_from_fov(320, 240, 185.0)
    lband = make_caster(world, "open3d", lband_only=True)
    frames_m = np.arange(150.0, 551.0, 10.0)
    pos = np.arange(300.0, 400.0, 1.0)
    params = ReconstructionParams(reach_m=100.0, carve_range_m=50.0)
    truths = {
        "truth before": true_masks(world, pos, caster=lband, thin_rule=False).mask_el_deg,
        "truth after": true_masks(world, pos, caster=lband).mask_el_deg,
    }
    changed = int((np.abs(truths["truth after"] - truths["truth before"]) > 0.1).sum())
    print(f"truth bins the rule changes: {changed} of {pos.size * 720}")
    for name, thin_deg in (("masks before", None), ("masks after", 0.7)):
        frames = ideal_frames(world, frames_m, cam, caster=lband, thin_deg=thin_deg)
        mask = Reconstructor(params).run(frames, pos, track).mask_el_deg
        for tname, truth in truths.items():
            trusted, good, visible = trust_counts(mask, truth, 0.0, EL_STEP_DEG)
            bad = int(trusted.sum() - good.sum())
            print(f"{name:13s} vs {tname:12s}: false trust {100 * bad / trusted.sum():.4f} % "
                  f"({bad} directions), sky lost {100 * (1 - good.sum() / visible.sum()):.2f} %")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    ).parse_args()  # no options: --help describes the run instead of starting it
    main()
