"""Partitioned trust (locator.partition) in a world with a wall at one end of the interval.

Ground truth is independent of the code under test: which satellites are blocked where comes
from ray casting the world's mesh (predisat.synth.raycast), the masks from the true-mask
ray caster, the claim's safety from intervals built around a known truth.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from locator.fde import LocatorConfig
from locator.partition import combine_stretches, trust_stretches
from locator.run import RunConfig, run_locator
from locator.sathia import AntennaPath
from locator.selection import select_satellites
from locator.sources import EpochData
from predisat.geodesy import azel_to_enu
from predisat.gnss.integrity import IntegrityBudget
from predisat.masks.maskset import MaskSet
from predisat.synth.materials import material_id
from predisat.synth.raycast import make_caster
from predisat.synth.truth import true_masks
from predisat.synth.world import Stretch, World, WorldSpec
from tests.locator._scene import canyon_track, ranges, sky

ANTENNA_M = 4.0
WALL_FROM_M = 300.0  # the wall stands west of the track from this chainage on
# 8 satellites; a 30 m wall 10 m west blocks those at azimuths 200, 240, 300 and 340 deg
AZ = np.array([10.0, 60.0, 100.0, 150.0, 200.0, 240.0, 300.0, 340.0])
EL = np.array([70.0, 25.0, 40.0, 55.0, 30.0, 20.0, 45.0, 35.0])
NAMES = tuple(f"G{k + 1:02d}" for k in range(len(AZ)))


def wall_world() -> World:
    """A north-bound straight track (chainage = metres north), a smooth 30 m wall 10 m west
    of it from chainage 300 to 700, open sky before."""
    track = canyon_track()
    y0, y1, x, top = WALL_FROM_M, 700.0, -10.0, 30.0
    v = np.array([[x, y0, -1.0], [x, y1, -1.0], [x, y1, top], [x, y0, top]])
    f = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    mat = np.full(len(f), material_id("rock"), np.int16)
    spec = WorldSpec((Stretch("rock_walls", 0.0, 600.0),), catenary=False, hills=False)
    return World(track, track.frame, spec, 0, v, f, mat)


@pytest.fixture(scope="module")
def scene():
    world = wall_world()
    tm = true_masks(world, np.arange(0.0, 601.0, 10.0), ANTENNA_M)
    masks = MaskSet.from_arrays(tm.chainage_m, tm.lat_deg, tm.lon_deg, tm.h_m, tm.heading_deg,
                                tm.mask_el_deg, margin_deg=1.0)  # fmt: skip
    caster = make_caster(world, lband_only=True)
    return world, masks, caster


def blocked(world: World, caster, chainage_m) -> np.ndarray:
    """Ray cast: whether each satellite is hidden from the antenna at each chainage, (n, 8).

    The direction is the satellite's at the frame origin: over 600 m it turns by 0.005 deg."""
    s = np.atleast_1d(np.asarray(chainage_m, float))
    ant = world.antenna_enu(s, ANTENNA_M)
    d = azel_to_enu(AZ, EL)
    o = np.repeat(ant, len(AZ), axis=0)
    return caster.occluded(o, np.tile(d, (len(s), 1))).reshape(len(s), len(AZ))


def test_the_wall_blocks_the_western_satellites_under_it_only(scene):
    world, _, caster = scene
    b = blocked(world, caster, [100.0, 250.0, 350.0, 550.0])
    west = np.isin(AZ, [200.0, 240.0, 300.0, 340.0])
    assert not b[:2].any()
    assert (b[2:] == west).all()


def test_stretches_keep_the_open_end_and_never_trust_where_blocked(scene):
    world, masks, caster = scene
    lo, hi = 150.0, 450.0
    # the single set: every western satellite dropped over the whole interval
    single = select_satellites(masks, lo, hi, AZ, EL).trusted
    assert single.sum() == 4 and not single[4:].any()
    st = trust_stretches(masks, lo, hi, AZ, EL, max_stretches=3, sats=NAMES)
    assert 1 < len(st) <= 3
    assert st[0].lo_m == lo and st[-1].hi_m == hi
    assert all(a.hi_m == b.lo_m for a, b in itertools.pairwise(st))
    # the open end trusts all eight
    assert st[0].selection.trusted.all() and st[0].hi_m >= 270.0  # G08 (NNW) meets it at 280
    for s in st:
        # the ray cast at the positions the masks were sampled at (a mask stands for its 10 m
        # cell: between samples a wall's end can hide a satellite the cell's mask shows, for
        # the single set as for the stretches; e.g. G08 at 272-275 m, cell 265-275 m)
        probe = masks.chainage_m[(masks.chainage_m >= s.lo_m) & (masks.chainage_m <= s.hi_m)]
        hidden = blocked(world, caster, probe).any(axis=0)
        # never trusted where the ray cast finds the satellite hidden
        assert not (s.selection.trusted & hidden).any(), (s.lo_m, s.hi_m)
        # a stretch's set holds the single set (it is never worse)
        assert (s.selection.trusted >= single).all()


def test_one_stretch_when_the_set_does_not_change(scene):
    _, masks, _ = scene
    st = trust_stretches(masks, 100.0, 250.0, AZ, EL, max_stretches=3)
    assert len(st) == 1 and st[0].selection.trusted.all()
    # and outside coverage nothing is trusted (the part beyond the masks is its own stretch)
    st = trust_stretches(masks, 560.0, 640.0, AZ, EL, max_stretches=3)
    assert st[-1].lo_m == pytest.approx(605.0) and not st[-1].selection.trusted.any()


def test_guards(scene):
    _, masks, _ = scene
    with pytest.raises(ValueError, match="max_stretches"):
        trust_stretches(masks, 100.0, 200.0, AZ, EL, max_stretches=0)
    with pytest.raises(ValueError, match="lo <= hi"):
        trust_stretches(masks, 200.0, 100.0, AZ, EL)
    with pytest.raises(ValueError, match="trust_stretches"):
        RunConfig(trust_stretches=0)


def test_combine_keeps_each_claim_inside_its_stretch():
    # stretches [0, 10], [10, 20], [20, 30]; the middle claim spills into both neighbours
    c = combine_stretches([0, 10, 20], [10, 20, 30], [True, True, True],
                          [-5, 8, 40], [2, 25, 50], [0, 15, 45])  # fmt: skip
    # both estimates lie in their own parts: the shorter fix (7 m against 17 m) is chosen
    assert (c.lo_m, c.hi_m, c.claim, c.conflict, c.chosen) == (0.0, 20.0, True, False, 0)
    # with counts: the fix that used the fewest satellites gives the estimate
    c = combine_stretches([0, 10, 20], [10, 20, 30], [True, True, True],
                          [-5, 8, 40], [2, 25, 50], [0, 15, 45], n_used=[8, 6, 4])  # fmt: skip
    assert (c.lo_m, c.hi_m, c.claim, c.chosen) == (0.0, 20.0, True, 1)
    # a hull that is the whole prediction says nothing the odometry does not: no claim
    c = combine_stretches([0, 10], [10, 20], [True, False], [-5, np.nan], [3, np.nan],
                          [1, np.nan])  # fmt: skip
    assert (c.lo_m, c.hi_m, c.claim, c.conflict) == (0.0, 20.0, False, False)
    # an unclaimed stretch is kept whole
    c = combine_stretches([0, 10, 20], [10, 20, 30], [True, True, False],
                          [12, 12, np.nan], [14, 14, np.nan], [13, 13, np.nan])  # fmt: skip
    assert (c.lo_m, c.hi_m, c.claim) == (12.0, 30.0, True)
    # every claim outside its own stretch and nothing kept whole: a conflict, no claim
    c = combine_stretches([0, 10], [10, 20], [True, True], [12, 2], [14, 4], [13, 3])
    assert c.conflict and not c.claim
    # estimates outside the prediction: a conflict with the estimate rule only
    lo, hi, claimed = [0, 10, 20], [10, 20, 30], [True, False, True]
    fl, fh, est = [-20, np.nan, 40], [1, np.nan, 50], [-10, np.nan, 45]
    c = combine_stretches(lo, hi, claimed, fl, fh, est)
    assert c.conflict and not c.claim
    c = combine_stretches(lo, hi, claimed, fl, fh, est, estimate_inside=False)
    assert c.claim and (c.lo_m, c.hi_m) == (0.0, 20.0)


def test_combined_claim_holds_the_truth_whenever_its_stretch_fix_does():
    """The safety argument, checked on random layouts: the truth in stretch j*, the fix of j*
    holds it (or makes no claim), every other fix anywhere: a claim then holds the truth."""
    rng = np.random.default_rng(7)
    n_claims = 0
    for _ in range(4000):
        n = int(rng.integers(1, 5))
        edges = np.sort(rng.uniform(0.0, 300.0, n + 1))
        a, b = edges[:-1], edges[1:]
        j = int(rng.integers(n))
        truth = rng.uniform(a[j], b[j])
        claimed = rng.random(n) < 0.8
        centre = rng.uniform(-100.0, 400.0, n)  # other fixes: anywhere (NLOS, faults)
        half = rng.uniform(1.0, 60.0, n)
        centre[j] = truth + rng.uniform(-0.9, 0.9) * half[j]  # the valid fix holds the truth
        est = centre + rng.normal(0.0, 5.0, n)
        for rule in (True, False):
            c = combine_stretches(a, b, claimed, centre - half, centre + half, est,
                                  estimate_inside=rule)  # fmt: skip
            if c.claim:
                n_claims += 1
                assert c.lo_m <= truth <= c.hi_m
    assert n_claims > 3000


class WallSource:
    """Ranges made at the true chainage; a satellite the ray cast finds hidden there gets an
    NLOS delay of 40 m (a reflection off the wall's far side would be longer still)."""

    def __init__(self, path: AntennaPath, truth_m, hidden, seed=0):
        self.path, self.truth_m, self.hidden = path, np.asarray(truth_m, float), hidden
        self.sat = sky(path.ecef_at(self.truth_m[0]), AZ, EL)
        self.rng = np.random.default_rng(seed)
        self.gps_s = np.arange(len(self.truth_m), dtype=float)
        self.odometer_m = self.truth_m - self.truth_m[0]

    def observe(self, k, rx_ecef_m):
        rho = ranges(self.sat, self.path.ecef_at(self.truth_m[k]), 0.5, self.rng)
        return EpochData(NAMES, self.sat, rho + 40.0 * self.hidden[k], {})

    def describe(self):
        return {"source": "wall"}


def test_run_into_the_wall_keeps_satellites_and_never_misleads(scene):
    world, masks, caster = scene
    path = AntennaPath(world.track, ANTENNA_M)
    truth = np.arange(120.0, 520.0, 8.0)
    hidden = blocked(world, caster, truth)
    out = {}
    for n in (1, 3):
        cfg = RunConfig(LocatorConfig(budget=IntegrityBudget()), trust="masks",
                        trust_stretches=n, start_uncertainty_m=60.0)  # fmt: skip
        ep = run_locator(path, WallSource(path, truth, hidden), start_chainage_m=truth[0],
                         config=cfg, masks=masks)  # fmt: skip
        claim = ep["claim"].to_numpy()
        inside = (ep["lo_m"] <= truth) & (truth <= ep["hi_m"])
        assert claim.mean() > 0.75
        assert inside[claim].all(), f"trust_stretches={n}: a claim missed the truth"
        fused = ep["fused_hi_m"] - ep["fused_lo_m"]
        ep["tightens"] = ep["claim"] & (fused < ep["pred_hi_m"] - ep["pred_lo_m"] - 1.0)
        out[n] = ep
    # the train in the open, the prediction's far end already where the ray cast hides a
    # satellite: the single set loses it over the whole prediction, and its claims are longer
    # than the stretches' (whose open stretch keeps it)
    open_here = ~hidden.any(axis=1)
    far_hidden = blocked(world, caster, out[1]["pred_hi_m"].to_numpy()).any(axis=1)
    near = open_here & far_hidden
    assert near.sum() >= 3
    assert (out[1]["n_trusted"].to_numpy()[near] < len(AZ)).all()
    len1, len3 = out[1]["length_m"].to_numpy()[near], out[3]["length_m"].to_numpy()[near]
    assert (len3 <= len1).all() and (len3 < len1 - 5.0).sum() >= 3
    # claims that tighten the odometry prediction: no fewer
    assert out[3]["tightens"].sum() >= out[1]["tightens"].sum()
