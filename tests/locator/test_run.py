"""Tests of the epoch loop (locator.run) on synthetic geometry with known truth.

Pseudoranges are Euclidean distances from the true antenna position to satellites at chosen
directions plus a clock and Gaussian noise (tests/locator/_scene.py); the truth is the chainage
the ranges were made at.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from locator.fde import FixFlag, LocatorConfig
from locator.run import RunConfig, RunFlag, flag_names, run_locator
from locator.sources import EpochData
from predisat.geodesy import ecef_to_geodetic, enu_rotation
from predisat.gnss.errormodel import ErrorModel, IntervalModel
from predisat.masks.maskset import MaskSet
from predisat.track.alias import TrackAliases
from tests.locator._scene import balloon_path, ranges, sky, straight_path

SIGMA_M = 1.0
MODEL = LocatorConfig(
    model=IntervalModel(ErrorModel(a_m=0.7, b_m=0.7), k_sigma=3.0), budget=None
)
# az, el of 8 satellites seen from the start; the track runs toward azimuth 60 deg
AZ = np.array([10.0, 60.0, 100.0, 150.0, 200.0, 240.0, 300.0, 340.0])
EL = np.array([70.0, 25.0, 40.0, 55.0, 30.0, 20.0, 45.0, 35.0])


class FakeSource:
    """Ranges at known chainages; optional bias per (epoch, satellite) and odometer."""

    def __init__(self, path, truth_m, bias_m=None, odometer_m=None, seed=0):
        self.path = path
        self.truth_m = np.asarray(truth_m, float)
        x0 = path.ecef_at(self.truth_m[0])
        self.sat = sky(x0, AZ, EL)
        self.names = tuple(f"G{k + 1:02d}" for k in range(len(AZ)))
        self.bias = np.zeros((len(self.truth_m), len(AZ))) if bias_m is None else bias_m
        self.odo = self.truth_m - self.truth_m[0] if odometer_m is None else odometer_m
        self.rng = np.random.default_rng(seed)
        self.gps_s = np.arange(len(self.truth_m), dtype=float)

    @property
    def odometer_m(self):
        return self.odo

    def observe(self, k, rx_ecef_m):
        x = self.path.ecef_at(self.truth_m[k])
        rho = ranges(self.sat, x, SIGMA_M * 0.5, self.rng) + self.bias[k]
        return EpochData(self.names, self.sat, rho, {})

    def describe(self):
        return {"source": "fake"}


@pytest.fixture(scope="module")
def path():
    return straight_path(heading_deg=60.0, length_m=4000.0)


def truth_run(n=40, start=1000.0, speed=15.0):
    return start + speed * np.arange(n)


def test_clean_run_claims_and_contains_the_truth(path):
    truth = truth_run()
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    assert len(ep) == len(truth)
    assert ep["claim"].all()
    assert (ep["mode"] == "three_pairs").all()
    assert ((ep["lo_m"] <= truth) & (truth <= ep["hi_m"])).all()
    assert np.abs(ep["chainage_m"] - truth).max() < 10.0
    # the odometry prediction (last interval moved by the odometer) holds the truth too
    assert ((ep["pred_lo_m"] <= truth) & (truth <= ep["pred_hi_m"])).all()
    assert (ep["n_used"] == len(AZ)).all() and (ep["excluded"] == "").all()


def test_mask_keeps_out_satellites_in_a_blocked_sector(path):
    truth = truth_run()
    c = np.arange(0.0, 4001.0, 10.0)
    az_bins = np.arange(0.0, 360.0, 1.0)
    # a 60 deg wall over azimuths 90-260 (satellites G03, G04, G05 and G06)
    mask = np.where((az_bins >= 90) & (az_bins <= 260), 60.0, 0.0)
    masks = MaskSet.from_track(path.track, c, np.tile(mask, (len(c), 1)))
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="masks"), masks=masks)  # fmt: skip
    blocked = {"G03", "G04", "G05", "G06"}
    for used, excl in zip(ep["used"], ep["excluded"], strict=True):
        assert blocked.isdisjoint(used.split())
        assert {item.split(":")[0] for item in excl.split()} == blocked
        assert all(item.endswith(":below_mask") for item in excl.split())
    assert (ep["n_trusted"] == 4).all() and (ep["mode"] == "all_pairs").all()


def test_cutoff_excludes_low_satellites(path):
    truth = truth_run(n=5)
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="cutoff", cutoff_deg=26.0))  # fmt: skip
    low = {f"G{k + 1:02d}" for k in np.flatnonzero(EL < 26.0)}
    for excl in ep["excluded"]:
        assert {i.split(":")[0] for i in excl.split()} == low
        assert all(i.endswith(":below_cutoff") for i in excl.split())


def test_fde_excludes_a_biased_satellite(path):
    truth = truth_run(n=10)
    bias = np.zeros((len(truth), len(AZ)))
    bias[5:, 1] = 60.0  # G02 turns NLOS-like from epoch 5
    ep = run_locator(path, FakeSource(path, truth, bias_m=bias), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    assert all("G02:fde" in e for e in ep["excluded"][5:])
    assert not any("G02" in e for e in ep["excluded"][:5])
    ok = ep["claim"].to_numpy()
    assert ((ep["lo_m"] <= truth) & (truth <= ep["hi_m"]))[ok].all()


def test_odometry_conflict_voids_the_claim(path):
    truth = truth_run(n=12)
    odo = truth - truth[0]
    odo[6:] += 400.0  # the odometer jumps 400 m ahead (slip, wrong reading)
    ep = run_locator(path, FakeSource(path, truth, odometer_m=odo), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    assert ep["claim"][:6].all()
    assert (ep["flags"][6] & RunFlag.ODOMETRY_CONFLICT) and not ep["claim"][6]
    assert "ODOMETRY_CONFLICT" in ep["flag_names"][6]
    assert ep["claim_fix"][6]  # the GNSS fix itself claimed: only the cross-check caught it
    # without the check the same epoch is claimed
    off = run_locator(path, FakeSource(path, truth, odometer_m=odo), start_chainage_m=truth[0],
                      config=RunConfig(MODEL, trust="none", odometry_check=False))  # fmt: skip
    assert off["claim"][6]


def test_no_odometer_bounds_motion_by_max_speed(path):
    truth = np.full(6, 2000.0)
    src = FakeSource(path, truth)
    src.odo = None
    ep = run_locator(path, src, start_chainage_m=2000.0, config=RunConfig(MODEL, trust="none"))
    width = ep["pred_hi_m"] - ep["pred_lo_m"]
    # after a claimed epoch the prediction is that interval +- (5 m + 45 m/s * 1 s)
    assert np.allclose(width[1:], (ep["hi_m"] - ep["lo_m"])[:-1] + 2 * 50.0)


def test_too_few_satellites_make_no_claim(path):
    truth = truth_run(n=3)
    src = FakeSource(path, truth)
    src.sat, src.names = src.sat[:3], src.names[:3]
    src.bias = src.bias[:, :3]
    ep = run_locator(path, src, start_chainage_m=truth[0], config=RunConfig(MODEL, trust="none"))
    assert (ep["mode"] == "best_pair").all() and not ep["claim"].any()
    assert all("NO_SAFETY_CLAIM" in f for f in ep["flag_names"])


def test_guards(path):
    src = FakeSource(path, truth_run(n=2))
    with pytest.raises(ValueError, match="needs masks"):
        run_locator(path, src, start_chainage_m=1000.0, config=RunConfig(trust="masks"))
    with pytest.raises(ValueError, match="off the track"):
        run_locator(path, src, start_chainage_m=-5.0, config=RunConfig(trust="none"))
    with pytest.raises(ValueError, match="trust must be"):
        RunConfig(trust="maybe")


def test_flag_names():
    assert flag_names(0) == ""
    f = int(FixFlag.NO_SAFETY_CLAIM | FixFlag.HEADING_FAIL | RunFlag.ODOMETRY_CONFLICT)
    assert flag_names(f) == "NO_SAFETY_CLAIM|HEADING_FAIL|ODOMETRY_CONFLICT"


class UncorrectedSource(FakeSource):
    """The FakeSource with a common ionosphere-like bias on every satellite and the extra
    sigma a source without any ionosphere model reports."""

    def __init__(self, path, truth_m, extra_m):
        super().__init__(path, truth_m)
        self.extra = np.full(len(AZ), extra_m)

    def observe(self, k, rx_ecef_m):
        d = super().observe(k, rx_ecef_m)
        return d._replace(extra_sigma_m=self.extra)


def test_uncorrected_ionosphere_is_flagged_and_widens_the_intervals(path):
    truth = truth_run(n=10)
    cfg = RunConfig(MODEL, trust="none")
    base = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0], config=cfg)
    none = run_locator(
        path, UncorrectedSource(path, truth, 0.0), start_chainage_m=truth[0], config=cfg
    )
    wide = run_locator(
        path, UncorrectedSource(path, truth, 5.0), start_chainage_m=truth[0], config=cfg
    )
    assert not base["iono_uncorrected"].any() and not none["iono_uncorrected"].any()
    assert wide["iono_uncorrected"].all()
    assert wide["flag_names"].str.contains("IONO_UNCORRECTED").all()
    assert not base["flag_names"].str.contains("IONO_UNCORRECTED").any()
    np.testing.assert_allclose(none["length_m"], base["length_m"])
    assert (wide["length_m"] > 2.0 * base["length_m"]).all()


def test_no_applicable_error_model_gives_positions_without_claim(path):
    truth = truth_run(n=6)
    src = FakeSource(path, truth)
    cfg = RunConfig(MODEL, trust="none", error_model_applies=False)
    ep = run_locator(path, src, start_chainage_m=truth[0], config=cfg)
    assert not ep["claim"].any()
    assert ep["flag_names"].str.contains("NO_ERROR_MODEL").all()
    # the positions are there, and as good as with the model
    assert np.abs(ep["chainage_m"] - truth).max() < 10.0
    assert ((ep["flags"].to_numpy(int) & int(RunFlag.NO_ERROR_MODEL)) > 0).all()


def test_satellites_below_the_model_range_are_left_out(path):
    truth = truth_run(n=4)
    cfg = RunConfig(MODEL, trust="none", model_el_min_deg=32.0)
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0], config=cfg)
    low = {f"G{k + 1:02d}" for k in np.flatnonzero(EL < 32.0)}
    assert len(low) == 3
    for excl, used in zip(ep["excluded"], ep["used"], strict=True):
        assert {i.split(":")[0] for i in excl.split() if i.endswith(":below_model")} == low
        assert not low & set(used.split())
    with pytest.raises(ValueError, match="model_el_min_deg"):
        RunConfig(MODEL, model_el_min_deg=95.0)


def test_satellites_above_the_model_range_are_left_out(path):
    # a user trial: a model fitted up to 60.7 deg took satellites up to 72.7 deg elsewhere
    truth = truth_run(n=4)
    top = float(np.sort(EL)[-2]) - 0.5  # the two highest lie above the model's range
    cfg = RunConfig(MODEL, trust="none", model_el_max_deg=top)
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0], config=cfg)
    high = {f"G{k + 1:02d}" for k in np.flatnonzero(EL > top)}
    assert len(high) == 2
    for excl, used in zip(ep["excluded"], ep["used"], strict=True):
        assert {i.split(":")[0] for i in excl.split() if i.endswith(":above_model")} == high
        assert not high & set(used.split())
    with pytest.raises(ValueError, match="model_el_max_deg"):
        RunConfig(MODEL, model_el_min_deg=30.0, model_el_max_deg=20.0)


def test_a_long_prediction_trusts_a_satellite_only_above_the_mask_at_both_ends(path):
    from pyproj import Transformer

    # one epoch at 2000 m; G06 is behind the train (az 240, el 20 deg seen from 2000 m), so
    # its elevation falls along the track: lowest at the prediction's far end
    truth = np.array([2000.0])
    src = FakeSource(path, truth)
    to_lla = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)

    def el_deg(chainage_m):  # independent geometry: the ellipsoid normal from PROJ
        x = path.ecef_at(chainage_m)
        lon, lat = np.radians(to_lla.transform(*x)[:2])
        up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
        los = src.sat[5] - x
        return np.degrees(np.arcsin(los @ up / np.linalg.norm(los)))

    half = 1500.0
    low, centre = el_deg(2000.0 + half), el_deg(2000.0)
    assert 0.01 < centre - low < 0.05  # what the centre's direction would overlook
    c = np.arange(0.0, 4001.0, 10.0)
    mask = np.zeros(360)
    mask[240] = 0.5 * (low + centre)  # above the satellite at the far end only
    masks = MaskSet.from_track(path.track, c, np.tile(mask, (len(c), 1)))
    for unc, trusted in ((50.0, True), (half, False)):
        cfg = RunConfig(MODEL, trust="masks", start_uncertainty_m=unc)
        ep = run_locator(path, src, start_chainage_m=truth[0], config=cfg, masks=masks)
        assert ("G06:below_mask" not in ep["excluded"][0]) == trusted, unc


@pytest.mark.parametrize("conflict", ["overlap", "estimate"])
def test_a_train_past_the_end_of_the_track_map_gets_no_claim_the_end_bounds(conflict):
    line = straight_path(heading_deg=60.0, length_m=8000.0)  # where the train really runs
    mapped = straight_path(heading_deg=60.0, length_m=4000.0)  # the map: its first 4 km
    truth = 3800.0 + 5.0 * np.arange(60)  # 3800 -> 4095 m: off the map for the last 19 s
    c = np.arange(0.0, 4001.0, 10.0)
    masks = MaskSet.from_track(mapped.track, c, np.full((len(c), 360), 5.0))
    cfg = RunConfig(MODEL, trust="masks", start_uncertainty_m=10.0, odometry_conflict=conflict)
    # the ranges are made on the line, the locator works on the map
    ep = run_locator(mapped, FakeSource(line, truth), start_chainage_m=truth[0], config=cfg,
                     masks=masks)  # fmt: skip
    claim = ep["claim"].to_numpy(bool)
    inside = (ep["lo_m"] <= truth) & (truth <= ep["hi_m"])
    assert claim[truth < 3950.0].any()  # on the map, away from its end: claims as before
    assert not (claim & ~inside).any()  # no claim misses the train, on the map or off it
    off = truth > mapped.length_m
    assert ep["flag_names"][off].str.contains("TRACK_END").all()
    assert not claim[off].any()
    # the loss is put down to the end only where the end voided a claim
    from locator.evaluate import claim_losses

    voided = ep["flag_names"].str.contains("CLAIM_AT_TRACK_END")
    assert voided.any() and not (voided & ep["claim"]).any()
    cause = "interval bounded by an end of the track map (the train may be past it)"
    assert claim_losses(ep).get(cause, 0.0) == pytest.approx(voided.mean())


def test_odometry_through_a_reversal_keeps_the_train_inside_the_prediction(path):
    from locator.sources import EpochData

    # a shunting move in a cutting (no satellite): 1050 m forward, 940 m back; the odometer
    # under-reads the first leg by 5 % and over-reads the second by 5.3 %, within 5 m + 5 %
    # of each leg but not of the 110 m net displacement
    truth = np.concatenate([1000.0 + 15.0 * np.arange(71), [2050.0],
                            2050.0 - 15.0 * np.arange(1, 63), [1110.0]])  # fmt: skip
    odo = np.empty_like(truth)
    odo[:72] = (truth[:72] - 1000.0) / 1.05
    odo[72:] = odo[71] - (2050.0 - truth[72:]) * (990.0 / 940.0)

    class NoSky:
        gps_s = np.arange(len(truth), dtype=float)
        odometer_m = odo

        def observe(self, k, rx):
            return EpochData((), np.zeros((0, 3)), np.zeros(0), {})

    ep = run_locator(path, NoSky(), start_chainage_m=1000.0,
                     config=RunConfig(trust="none", start_uncertainty_m=5.0))  # fmt: skip
    assert ((ep["fused_lo_m"] <= truth) & (truth <= ep["fused_hi_m"])).all()
    assert ep["odo_since_anchor_m"].iloc[-1] == pytest.approx(odo[71] + odo[71] - odo[-1])


class _AxisSky(FakeSource):
    """Satellites near the track's axis (a cutting): the across-track offset from the beacon,
    hence the heading, cannot be told."""

    def __init__(self, path, truth_m):
        super().__init__(path, truth_m)
        az = np.array([55.0, 62.0, 66.0, 236.0, 243.0, 250.0])
        el = np.array([20.0, 45.0, 70.0, 25.0, 50.0, 65.0])
        self.sat = sky(path.ecef_at(self.truth_m[0]), az, el)
        self.names = self.names[: len(az)]
        self.bias = np.zeros((len(self.truth_m), len(az)))


def test_a_claim_the_heading_check_could_not_judge_says_so(path):
    truth = truth_run(n=12)
    for source, some_unchecked in ((FakeSource, False), (_AxisSky, True)):
        ep = run_locator(path, source(path, truth), start_chainage_m=truth[0],
                         config=RunConfig(MODEL, trust="none"))  # fmt: skip
        status = ep["heading_status"].to_numpy(str)
        flagged = ep["flag_names"].str.contains("HEADING_UNCHECKED").to_numpy(bool)
        assert np.array_equal(flagged, (status == "unobservable") | (status == ""))
        assert flagged.any() == some_unchecked and ep["claim"].any()
        off = run_locator(path, source(path, truth), start_chainage_m=truth[0],
                          config=RunConfig(MODEL, trust="none", heading_check=False))  # fmt: skip
        assert not off["flag_names"].str.contains("HEADING_UNCHECKED").any()
        assert off["claim"].equals(ep["claim"])  # said, not voided


def test_satellites_trusted_where_the_mask_rests_on_no_view_are_counted_and_flagged(path):
    from predisat.masks.maskset import BinSource

    truth = truth_run(n=5)
    c = np.arange(0.0, 4001.0, 10.0)
    az_bins = np.arange(360)
    source = np.full((len(c), 360), int(BinSource.OBSERVED))
    # the far field beyond the corridor in the sector of G05 (az 200) and G06 (240): assumed
    far = (az_bins >= 190) & (az_bins <= 250)
    source[:, far] = int(BinSource.ASSUMED)
    masks = MaskSet.from_track(path.track, c, np.zeros((len(c), 360)), source=source)
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="masks"), masks=masks)  # fmt: skip
    in_far = {f"G{k + 1:02d}" for k in np.flatnonzero((AZ >= 190) & (AZ <= 250))}
    expected = [len(in_far & set(u.split())) for u in ep["used"]]
    assert ep["n_used_assumed"].tolist() == expected and max(expected) == 2
    flagged = ep["flag_names"].str.contains("ASSUMED_MASK")
    assert (flagged == (ep["n_used_assumed"] > 0)).all()
    assert ep["claim"].all()  # said, not voided
    plain = MaskSet.from_track(path.track, c, np.zeros((len(c), 360)))
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="masks"), masks=plain)  # fmt: skip
    assert (ep["n_used_assumed"] == 0).all() and not ep["flag_names"].str.contains("ASSUMED").any()


def test_a_hole_in_masks_joined_in_memory_trusts_nothing(path):
    from predisat.masks.maskset import concat_masksets

    truth = truth_run(n=3, start=2000.0, speed=5.0)
    c = np.arange(0.0, 4001.0, 10.0)
    whole = MaskSet.from_track(path.track, c, np.zeros((len(c), 360)))
    holed = concat_masksets([whole.subset(0.0, 1500.0), whole.subset(2500.0, 4000.0)])
    cfg = RunConfig(MODEL, trust="masks", start_uncertainty_m=10.0)
    ok = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0], config=cfg,
                     masks=whole)  # fmt: skip
    assert (ok["n_trusted"] == len(AZ)).all()
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0], config=cfg,
                     masks=holed)  # fmt: skip
    assert (ep["n_trusted"] == 0).all() and not ep["claim"].any()


def test_after_a_conflict_the_odometry_is_suspect_until_fixes_agree_again(path):
    """One epoch's ranges put the train 300 m ahead (consistently: no fault the FDE can see):
    a conflict; the next fixes agree with the odometry, yet the prediction was the trust
    decision's ground only if the odometry was right: the next two are flagged and make no
    claim, the third (``odometry_reconfirm``) claims again."""
    truth = truth_run(n=14)
    x = path.ecef_at(truth[6])
    sat = sky(path.ecef_at(truth[0]), AZ, EL)
    u = (sat - x) / np.linalg.norm(sat - x, axis=1, keepdims=True)
    bias = np.zeros((len(truth), len(AZ)))
    bias[6] = -300.0 * (u @ path.tangent_ecef_at(np.array([truth[6]]))[0])
    src = FakeSource(path, truth, bias_m=bias)
    ep = run_locator(path, src, start_chainage_m=truth[0], config=RunConfig(MODEL, trust="none"))
    assert ep["claim"][:6].all() and ep["claim_fix"][6] and not ep["claim"][6]
    assert ep["fusion"][6] == "conflict"
    suspect = (ep["flags"].to_numpy() & int(RunFlag.ODOMETRY_SUSPECT)) != 0
    assert suspect.tolist() == [False] * 7 + [True, True] + [False] * 5
    assert not ep["claim"][7:9].any() and ep["claim"][9:].all()
    assert (ep["fusion"][7:9] == "suspect").all() and (ep["fusion"][9:] == "fused").all()
    assert "ODOMETRY_SUSPECT" in ep["flag_names"][7]
    # 0: the conflict alone is flagged, as before
    old = run_locator(path, FakeSource(path, truth, bias_m=bias), start_chainage_m=truth[0],
                      config=RunConfig(MODEL, trust="none", odometry_reconfirm=0))  # fmt: skip
    assert old["claim"][7:].all()
    with pytest.raises(ValueError, match="odometry_reconfirm"):
        RunConfig(MODEL, odometry_reconfirm=-1)


def test_a_blunt_fix_conflict_begins_the_suspicion_only_when_repeated(path):
    """Fixes whose claimed intervals (about 700 m) hold the whole prediction (about 115 m):
    one epoch's ranges put the estimate 120 m ahead, outside the prediction. That claim is
    voided (a conflict) under either rule; the odometry becomes suspect at once under
    ``"every"``, and under ``"repeated"`` (the default) only when the same bound is passed
    again 1-3 s later (at 10 Hz such false conflicts came 13 times as often per km as at 1 Hz
    and held the suspicion through tunnels)."""
    wide = LocatorConfig(model=IntervalModel(ErrorModel(a_m=40.0, b_m=40.0), k_sigma=3.0),
                         budget=None)  # fmt: skip
    truth = truth_run(n=14)
    sat = sky(path.ecef_at(truth[0]), AZ, EL)

    def run(shifts, rule):
        bias = np.zeros((len(truth), len(AZ)))
        for k, ahead_m in shifts.items():
            x = path.ecef_at(truth[k])
            u = (sat - x) / np.linalg.norm(sat - x, axis=1, keepdims=True)
            bias[k] = -ahead_m * (u @ path.tangent_ecef_at(np.array([truth[k]]))[0])
        ep = run_locator(path, FakeSource(path, truth, bias_m=bias), start_chainage_m=truth[0],
                         config=RunConfig(wide, trust="none", odometry_suspect=rule))  # fmt: skip
        blunt = (ep["lo_m"] <= ep["pred_lo_m"]) & (ep["hi_m"] >= ep["pred_hi_m"])
        assert blunt[list(shifts)].all()  # the case under test
        return ep["fusion"].tolist()

    f, c, s = "fused", "conflict", "suspect"
    assert run({6: 120.0}, "repeated") == [f] * 6 + [c] + [f] * 7
    assert run({6: 120.0}, "every") == [f] * 6 + [c, s, s] + [f] * 5
    # the same bound again 2 s later: suspect from there
    assert run({6: 120.0, 8: 120.0}, "repeated") == [f] * 6 + [c, f, c, s, s] + [f] * 3
    # the other bound: noise, not a drift
    assert run({6: 120.0, 8: -120.0}, "repeated") == [f] * 6 + [c, f, c] + [f] * 5
    with pytest.raises(ValueError, match="odometry_suspect"):
        RunConfig(MODEL, odometry_suspect="sometimes")


def test_a_stuck_direction_channel_is_flagged_wherever_the_fused_interval_misses(path):
    """The train runs 20 epochs one way and 20 back; the odometer's direction is stuck (it
    counts the distance run as forward: a trial's stuck direction channel or unannounced cab
    change). Every epoch whose fused interval misses the truth is flagged and claims nothing;
    with the conflict alone flagged, epochs without a fix (here: a blind stretch, no
    satellite in view) carried the wrong prediction without a word."""
    out_m = 1000.0 + 15.0 * np.arange(21)
    truth = np.concatenate([out_m, out_m[-2::-1]])
    odo = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(truth)))])
    bias = np.zeros((len(truth), len(AZ)))
    blind = np.zeros(len(truth), bool)
    blind[30:] = True  # every range off by kilometres, each its own way: no fix claims
    bias[blind] = np.random.default_rng(5).uniform(-5e3, 5e3, (int(blind.sum()), len(AZ)))
    for reconfirm, want_silent in ((3, False), (0, True)):
        src = FakeSource(path, truth, bias_m=bias, odometer_m=odo)
        cfg = RunConfig(MODEL, trust="none", odometry_reconfirm=reconfirm)
        ep = run_locator(path, src, start_chainage_m=truth[0], config=cfg)
        miss = ~((ep["fused_lo_m"] <= truth + 1e-6) & (truth <= ep["fused_hi_m"] + 1e-6))
        flagged = (ep["flags"].to_numpy() & int(RunFlag.ODOMETRY_CONFLICT
                                                 | RunFlag.ODOMETRY_SUSPECT)) != 0  # fmt: skip
        assert miss.sum() > 10
        assert not (ep["claim"].to_numpy() & miss.to_numpy()).any()
        assert (miss.to_numpy() & ~flagged).any() == want_silent


def test_balise_capture_skips_conflicting_and_suspect_epochs(path):
    """A reviewer's case: the stuck direction channel's run with every fix claiming; its
    conflicting epochs (fused interval 17-627 m off) were taken as located and captured a
    balise the train never reached."""
    from locator.balises.campaign import located_epochs

    out_m = 1000.0 + 15.0 * np.arange(21)
    truth = np.concatenate([out_m, out_m[-2::-1]])
    odo = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(truth)))])
    ep = run_locator(path, FakeSource(path, truth, odometer_m=odo), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    miss = ~((ep["fused_lo_m"] <= truth + 1e-6) & (truth <= ep["fused_hi_m"] + 1e-6)).to_numpy()
    assert miss.sum() > 10 and set(ep["fusion"][miss]) <= {"conflict", "suspect"}
    located = located_epochs(ep)
    assert located[:20].all() and not (located & miss).any()


def test_a_wrong_start_recovers_on_the_motion_bound(path):
    """The stored start position is 300 m behind the train (outside its +-50 m): every fix
    conflicts with the prediction. Before the recovery the run stayed suspect to its end; now,
    20 s into the suspicion, the odometer is set aside, the motion bound from the start grows
    over the train, the fixes agree with it and claim again, always around the truth; the
    odometer stays aside (a wrong start and a faulty odometer look alike). Without the start
    check, which tells them apart at the start (RunConfig.start_check_m: the next test)."""
    truth = truth_run(n=60)
    start = truth[0] - 300.0
    kept = run_locator(path, FakeSource(path, truth), start_chainage_m=start,
                       config=RunConfig(MODEL, trust="none", odometry_recover_s=None,
                                        start_check_m=None))  # fmt: skip
    assert not kept["claim"].any()
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=start,
                     config=RunConfig(MODEL, trust="none", start_check_m=None))  # fmt: skip
    claim = ep["claim"].to_numpy()
    assert claim[30:].all()  # claims again, and not before the 20 s
    assert not claim[:20].any()
    inside = (ep["fused_lo_m"] <= truth + 1e-6) & (truth <= ep["fused_hi_m"] + 1e-6)
    assert inside[claim].all()
    used = ep["odometer_used"].to_numpy()
    assert used[:20].all() and not used[22:].any()  # set aside for the rest of the run
    with pytest.raises(ValueError, match="odometry_recover_s"):
        RunConfig(MODEL, odometry_recover_s=0.0)


def test_an_odometer_that_keeps_conflicting_is_set_aside_for_the_run(path):
    """The odometer counts backward while the train runs forward (a stuck direction channel
    from the start): the recovery sets it aside for good and the run claims on the motion
    bound, around the truth."""
    truth = truth_run(n=90)
    odo = -(truth - truth[0])
    ep = run_locator(path, FakeSource(path, truth, odometer_m=odo), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    used = ep["odometer_used"].to_numpy()
    assert not used[-20:].any()
    claim = ep["claim"].to_numpy()
    assert claim[-20:].all()
    inside = (ep["fused_lo_m"] <= truth + 1e-6) & (truth <= ep["fused_hi_m"] + 1e-6)
    assert inside[claim].all()


def test_where_the_masks_trust_nothing_the_sky_checks_the_prediction(path):
    """The masks cover 980-1700 m only; the odometer counts backward (a stuck direction
    channel), so the prediction leaves the coverage toward chainage 0 while the train runs on:
    no satellite is trusted, no fix claims, and the odometry conflict could not be seen (a user
    trial: 101 of 103 intervals off the train, no flag). A 3-D fix of every satellite above the
    cut-off, projected on the track, now shows the prediction off: every epoch whose fused
    interval misses the train by more than the check's margin is flagged (closer misses are
    the check's blind spot: untrusted satellites' errors)."""
    truth = truth_run(n=40)  # 1000 -> 1585 m
    c = np.arange(980.0, 1701.0, 10.0)
    masks = MaskSet.from_track(path.track, c, np.zeros((len(c), 360)))
    odo = -(truth - truth[0])
    flagged_bits = int(RunFlag.ODOMETRY_CONFLICT | RunFlag.ODOMETRY_SUSPECT)
    for sky_check, want_silent in ((None, True), (300.0, False)):
        cfg = RunConfig(MODEL, trust="masks", sky_check_m=sky_check, odometry_recover_s=None)
        ep = run_locator(path, FakeSource(path, truth, odometer_m=odo), start_chainage_m=truth[0],
                         config=cfg, masks=masks)  # fmt: skip
        # misses by more than the check's margin (300 m): gross, what the check can see
        far = ((ep["fused_lo_m"] - 300.0 > truth) | (truth > ep["fused_hi_m"] + 300.0)).to_numpy()
        flagged = (ep["flags"].to_numpy() & flagged_bits) != 0
        assert far.sum() > 20 and not ep["claim"][far].any()
        assert (far & ~flagged).any() == want_silent
    assert np.nanmax(np.abs(ep["sky_check_m"] - truth)) < 5.0  # the check's own chainage
    with pytest.raises(ValueError, match="sky_check_m"):
        RunConfig(MODEL, sky_check_m=0.0)


def test_crossed_prediction_bounds_fall_back_to_the_motion_bound_and_are_a_conflict():
    """Each bound has its own anchor; a faulty odometer can carry them across each other (a
    recovery trial's stuck direction channel: lo 371 m above hi, and the stretch split
    raised). Crossed bounds are an odometry conflict, and the prediction is the motion bound
    from the two anchors, which holds whatever the odometer did."""
    from locator.odometry.confidence import OdometerAccuracy
    from locator.run import _Tracker

    gps = np.arange(5.0)
    odo = np.array([0.0, -10.0, -20.0, -30.0, -40.0])
    t = _Tracker.start(1000.0, 20.0, odo, gps)
    t.lo_anchor = (1050.0, -40.0, 3.0, 40.0, 0.0, 0.0)  # re-anchored high at epoch 3 ...
    t.hi_anchor = (990.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # ... the upper bound still at the start
    cfg = RunConfig(MODEL, odometer=OdometerAccuracy(abs_error_m=1.0, over_rel=0.05,
                                                     under_rel=0.05, max_speed_mps=40.0))
    lo, hi, _ = t.predict(4, gps, odo, cfg, 4000.0)
    assert t.inverted
    assert lo == pytest.approx(1050.0 - (1.0 + 40.0 * 1.0))
    assert hi == pytest.approx(990.0 + (1.0 + 40.0 * 4.0))


@pytest.mark.parametrize("gap_m", [3.4, 6.0])
def test_a_start_on_the_other_leg_of_a_balloon_loop_claims_nothing(gap_m):
    """A user trial: the train runs the return leg of a balloon loop, the start (a header
    position projected on the nearest leg) is on the outgoing leg beside it. The pair
    intersections are as good on either leg; once the odometer was set aside, the claims
    followed the wrong leg, every one off the train. Beside another stretch, a claim now
    stands only when the run was located where the track is alone."""
    p = balloon_path(gap_m)
    truth = 2250.0 + 10.0 * np.arange(70)
    start = p.length_m - truth[0]  # the place beside the train on the outgoing leg
    off = run_locator(p, FakeSource(p, truth), start_chainage_m=start,
                      config=RunConfig(MODEL, trust="none", alias_m=None))  # fmt: skip
    claim = off["claim"].to_numpy()
    inside = ((off["lo_m"] <= truth + 1e-6) & (truth <= off["hi_m"] + 1e-6)).to_numpy()
    assert (claim & ~inside).sum() > 20  # the hazard the check removes
    ep = run_locator(p, FakeSource(p, truth), start_chainage_m=start,
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    assert not ep["claim"].any()
    assert ep["flag_names"].str.contains("TRACK_ALIAS").sum() >= claim.sum()
    with pytest.raises(ValueError, match="alias_m"):
        RunConfig(MODEL, alias_m=0.0)


def test_a_run_located_on_the_loop_keeps_claiming_along_the_leg_beside_the_other():
    """Located where the track is alone, the odometer's prediction rules the other leg out:
    the claims go on along the return leg, each around the truth."""
    p = balloon_path(3.4)
    truth = 1900.0 + 10.0 * np.arange(100)
    ep = run_locator(p, FakeSource(p, truth), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    beside = TrackAliases.of(p.track)
    on_leg = np.array([beside.within(t, t).size > 0 for t in truth])
    assert on_leg.sum() >= 60
    claim = ep["claim"].to_numpy()
    assert claim[on_leg].all()
    inside = (ep["fused_lo_m"] <= truth + 1e-6) & (truth <= ep["fused_hi_m"] + 1e-6)
    assert inside[claim].all()


class _OffMapSource(FakeSource):
    """The antenna ``right_m`` to the right of the map (a branch the map lacks) and ``up_m``
    above it (a map whose heights are off) from epoch ``from_k`` on."""

    def __init__(self, path, truth_m, from_k, right_m=0.0, up_m=0.0):
        super().__init__(path, truth_m)
        self.from_k, self.right_m, self.up_m = from_k, right_m, up_m

    def observe(self, k, rx_ecef_m):
        x = self.path.ecef_at(self.truth_m[k])
        if k >= self.from_k:
            lat, lon, _ = ecef_to_geodetic(x)
            hd = np.radians(float(self.path.track.heading_at(self.truth_m[k])))
            shift_enu = np.array([self.right_m * np.cos(hd), -self.right_m * np.sin(hd),
                                  self.up_m])  # fmt: skip
            x = x + shift_enu @ enu_rotation(lat, lon)
        rho = ranges(self.sat, x, SIGMA_M * 0.5, self.rng) + self.bias[k]
        return EpochData(self.names, self.sat, rho, {})


def test_a_train_beside_the_map_gets_no_claim():
    """A user trial: a train that took a branch missing from the map got claims 5-42 m beside
    it; the 1-D fault detection let them through. Here the error model is looser than the
    ranges (as a model overbounding a receiver is), and 15 m beside the map the pairs stay
    consistent; the trusted satellites' 3-D fix, beyond the map's doubt and 5 of its
    cross-track sigmas (about 13 m here), voids those claims; on the map it voids none."""
    loose = LocatorConfig(model=IntervalModel(ErrorModel(a_m=2.0, b_m=2.0), k_sigma=3.0),
                          budget=None)  # fmt: skip
    p = straight_path()
    truth = truth_run(n=40)
    kept = run_locator(p, _OffMapSource(p, truth, 20, right_m=15.0), start_chainage_m=truth[0],
                       config=RunConfig(loose, trust="none", off_track_k_sigma=None))  # fmt: skip
    assert kept["claim"].iloc[20:].sum() >= 15  # without the check they stood
    ep = run_locator(p, _OffMapSource(p, truth, 20, right_m=15.0), start_chainage_m=truth[0],
                     config=RunConfig(loose, trust="none"))  # fmt: skip
    assert ep["claim"].iloc[:20].all()
    assert not ep["flag_names"].iloc[:20].str.contains("OFF_TRACK").any()
    assert ep["claim"].iloc[20:].sum() <= 6
    assert ep["flag_names"].iloc[20:].str.contains("OFF_TRACK").sum() >= 10
    np.testing.assert_allclose(ep["off_track_m"].iloc[:20], 0.0, atol=3.0)
    off = ep["off_track_m"].iloc[20:].dropna()
    assert len(off) >= 15 and np.all(np.abs(off - 15.0) < 5.0)
    with pytest.raises(ValueError, match="off_track_k_sigma"):
        RunConfig(MODEL, off_track_k_sigma=0.0)


@pytest.mark.parametrize("up_m", [15.0, -15.0])
def test_a_map_off_in_height_gets_no_claim(up_m):
    """A user trial on a real station: a track map 15-19 m too high or low passed the run's
    height check (20 m) and the 1-D fault detection excluded healthy satellites to absorb it:
    26 of 59 claims at one heading missed the train. The trusted satellites' 3-D fix, beyond
    the map's vertical doubt and 5 of its vertical sigmas, voids those claims. (A model as
    tight as the ranges, as one calibrated on the receiver: 5 vertical sigmas of a looser one
    reach past 15 m.)"""
    tight = LocatorConfig(model=IntervalModel(ErrorModel(a_m=0.5, b_m=0.5), k_sigma=3.0),
                          budget=None)  # fmt: skip
    p = straight_path()
    truth = truth_run(n=40)
    ep = run_locator(p, _OffMapSource(p, truth, 20, up_m=up_m), start_chainage_m=truth[0],
                     config=RunConfig(tight, trust="none"))  # fmt: skip
    assert ep["claim"].iloc[:20].all()
    np.testing.assert_allclose(ep["off_track_up_m"].iloc[:20], 0.0, atol=5.0)
    assert ep["claim"].iloc[20:].sum() <= 2
    assert ep["flag_names"].iloc[20:].str.contains("OFF_TRACK").sum() >= 12
    up = ep["off_track_up_m"].iloc[20:].dropna()
    assert len(up) >= 12 and np.all(np.abs(up - up_m) < 4.0)


def test_a_satellite_the_fix_excludes_does_not_put_the_train_off_the_track():
    """A review: one satellite biased 40 m, excluded by the 1-D fault detection, moved the 3-D
    fix off the map and voided correct claims; the 3-D fix now excludes it too. With four
    trusted satellites no 3-D fix checks the claim, and the flag says so."""
    p = straight_path()
    truth = truth_run(n=20)
    for sat in range(len(AZ)):
        bias = np.zeros((len(truth), len(AZ)))
        bias[:, sat] = 40.0
        ep = run_locator(p, FakeSource(p, truth, bias_m=bias), start_chainage_m=truth[0],
                         config=RunConfig(MODEL, trust="none"))  # fmt: skip
        assert not ep["flag_names"].str.contains(r"OFF_TRACK\b").any(), sat
    few = run_locator(p, FakeSource(p, truth), start_chainage_m=truth[0],
                      config=RunConfig(MODEL, trust="cutoff", cutoff_deg=36.0))  # fmt: skip
    claimed = few[few["claim"]]
    assert len(claimed) and (claimed["n_used"] < 5).all()
    assert claimed["flag_names"].str.contains("OFF_TRACK_UNCHECKED").all()


def _walled_masks(path, wall_below_m):
    """Masks every 10 m: a 60 deg wall over azimuths 290-350 (G07 at 300, G08 at 340 deg)
    before ``wall_below_m``, open sky after it."""
    c = np.arange(0.0, 4001.0, 10.0)
    az_bins = np.arange(0.0, 360.0, 1.0)
    wall = np.where((az_bins >= 290) & (az_bins <= 350), 60.0, 0.0)
    mask = np.where(c[:, None] < wall_below_m, wall[None, :], 0.0)
    return MaskSet.from_track(path.track, c, mask)


@pytest.mark.parametrize("stretches", [1, 16])
def test_a_start_the_satellites_contradict_is_flagged_and_its_masks_are_not_trusted_alone(
    path, stretches
):
    """A start 300 m ahead of the train (a trial on the demo line: no claim, but the masks of
    where the train was not chose the satellites for the whole run, 116 NLOS signals used,
    nothing said). Here the wall hides G07 and G08 where the train is (their signals arrive
    reflected, 40 m late) and the sky is open at the stated start. The sky fix of every
    satellite contradicts the start at its first two epochs: from the second one every epoch
    until a claim locates the run is flagged START_CONFLICT, the prediction covers both
    places, so the single set never trusts the hidden satellites again, and no claim misses
    the train."""
    truth = truth_run(n=40)  # 1000 -> 1585 m
    masks = _walled_masks(path, 1240.0)
    hidden = truth < 1240.0
    bias = np.zeros((len(truth), len(AZ)))
    bias[hidden, 6:8] = 40.0  # G07, G08: NLOS where the wall is
    cfg = RunConfig(MODEL, trust="masks", trust_stretches=stretches)
    ep = run_locator(path, FakeSource(path, truth, bias_m=bias),
                     start_chainage_m=truth[0] + 300.0, config=cfg, masks=masks)  # fmt: skip
    flagged = (ep["flags"].to_numpy() & int(RunFlag.START_CONFLICT)) != 0
    assert flagged[:2].all()  # from epoch 0: its fix's interval contradicts the start
    first_claim = int(np.flatnonzero(ep["claim"].to_numpy())[0])
    assert flagged[:first_claim + 1].all() and not flagged[first_claim + 1:].any()
    assert not ep["claim"][flagged][:-1].any()  # suspect until fixes agree: then one claims
    assert (ep["pred_lo_m"][1:] <= truth[1:]).all()  # the widened prediction holds the train
    assert np.nanmax(np.abs(ep["start_check_m"][:2] - truth[:2])) < 50.0
    assert np.isnan(ep["start_check_m"][first_claim + 1:]).all()  # located: no more checks
    claim = ep["claim"].to_numpy()
    assert claim.sum() > 10
    assert ((ep["lo_m"] <= truth) & (truth <= ep["hi_m"]))[claim].all()
    assert ((ep["fused_lo_m"] <= truth) & (truth <= ep["fused_hi_m"]))[claim].all()
    assert ep["odometer_used"].all()  # the start was wrong, not the odometer: kept
    if stretches == 1:  # the single set trusts only satellites in view wherever the train is
        assert not (_trusted_any(ep, "G07", "G08") & hidden)[1:].any()
    unchecked = dataclasses.replace(cfg, start_check_m=None)
    without = run_locator(path, FakeSource(path, truth, bias_m=bias), config=unchecked,
                          start_chainage_m=truth[0] + 300.0, masks=masks)  # fmt: skip
    # the defect: the stated start's masks trusted them wherever they were hidden, unflagged
    assert (_trusted_any(without, "G07", "G08") & hidden).sum() == hidden.sum()


def _trusted_any(ep, *sats):
    """Per epoch: whether any of ``sats`` passed the trust decision (not left out by a mask)."""
    out = []
    for text in ep["excluded"]:
        reasons = dict(item.split(":", 1) for item in str(text).split())
        out.append(any(reasons.get(s) not in ("below_mask", "outside_coverage") for s in sats))
    return np.array(out)


def test_a_start_30_m_off_is_flagged_when_beyond_its_stated_uncertainty(path):
    """30 m off with a stated uncertainty of 10 m (a balise's) and a check margin of 10 m: the
    train is not in the start's interval, the sky fix says so, the prediction is widened over
    both places and every claim holds the train. Within the default 50 m the same start is no
    contradiction (the train is inside the start's interval) and nothing is flagged."""
    truth = truth_run(n=30)
    src = FakeSource(path, truth)
    tight = RunConfig(MODEL, trust="none", start_uncertainty_m=10.0, start_check_m=10.0)
    ep = run_locator(path, src, start_chainage_m=truth[0] + 30.0, config=tight)
    flagged = (ep["flags"].to_numpy() & int(RunFlag.START_CONFLICT)) != 0
    assert flagged[1] and "START_CONFLICT" in ep["flag_names"][1]
    claim = ep["claim"].to_numpy()
    first_claim = int(np.flatnonzero(claim)[0])
    assert first_claim < 8 and claim.sum() > 20 and flagged[1:first_claim + 1].all()
    assert (ep["pred_lo_m"][1:] <= truth[1:]).all()  # widened over the train's place
    assert ((ep["fused_lo_m"] <= truth + 1e-6) & (truth <= ep["fused_hi_m"] + 1e-6))[claim].all()
    loose = RunConfig(MODEL, trust="none")
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0] + 30.0,
                     config=loose)  # fmt: skip
    assert not ep["flag_names"].str.contains("START_CONFLICT").any()


@pytest.mark.parametrize("trust", ["masks", "none"])
def test_a_right_start_is_not_flagged_and_its_run_unchanged(path, trust):
    """The start check only widens where the satellites contradict the start: a right start's
    run is the same, bit for bit, with the check or without it."""
    truth = truth_run(n=30)
    masks = _walled_masks(path, 1240.0) if trust == "masks" else None
    cfg = RunConfig(MODEL, trust=trust)
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0], config=cfg,
                     masks=masks)  # fmt: skip
    unchecked = dataclasses.replace(cfg, start_check_m=None)
    off = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0],
                      config=unchecked, masks=masks)  # fmt: skip
    assert not ep["flag_names"].str.contains("START_CONFLICT").any()
    assert np.isfinite(ep["start_check_m"][0])  # checked, agreeing
    cols = [c for c in ep.columns if c not in ("solve_ms", "start_check_m")]
    pd.testing.assert_frame_equal(ep[cols], off[cols])
    with pytest.raises(ValueError, match="start_check_m"):
        RunConfig(MODEL, start_check_m=0.0)
    with pytest.raises(ValueError, match="start_check_epochs"):
        RunConfig(MODEL, start_check_epochs=0)


def test_a_start_beyond_its_uncertainty_but_within_the_check_margin_is_widened_by_the_fix(path):
    """75 m off with the stated 50 m: the sky fix lies within ``start_check_m`` (50 m) of the
    prediction, so the sky check cannot tell, but every fix's claimed interval contradicts the
    prediction. Before a claim located the run, that conflict widens the prediction over the
    fix's interval (START_CONFLICT) instead of blaming the odometer: before, 20 s of conflicts
    set the healthy odometer aside and nothing was said of the start (a review: the demo
    case's single set then claimed nothing in 151 epochs)."""
    truth = truth_run(n=40)
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0] + 75.0,
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    flagged = (ep["flags"].to_numpy() & int(RunFlag.START_CONFLICT)) != 0
    claim = ep["claim"].to_numpy()
    first_claim = int(np.flatnonzero(claim)[0])
    assert flagged[0] and flagged[: first_claim + 1].all() and not flagged[first_claim + 1:].any()
    assert first_claim < 8 and claim.sum() > 30
    assert (ep["pred_lo_m"][1:] <= truth[1:]).all()  # widened over the train's place
    assert ep["odometer_used"].all()  # the start was wrong, not the odometer: kept
    assert ((ep["lo_m"] <= truth) & (truth <= ep["hi_m"]))[claim].all()
    assert ((ep["fused_lo_m"] <= truth + 1e-6) & (truth <= ep["fused_hi_m"] + 1e-6))[claim].all()
