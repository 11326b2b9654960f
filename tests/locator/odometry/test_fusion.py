"""Fusion of the odometry interval with satellite claims (locator.odometry.fusion, run loop)."""

from __future__ import annotations

import numpy as np
import pytest

from locator.odometry.confidence import OdometerAccuracy
from locator.odometry.fusion import (
    FusionStatus,
    blend_estimate,
    fuse_intervals,
    motion_bound,
    predict_estimate,
    predict_interval,
)
from locator.run import RunConfig, run_locator
from tests.locator._scene import straight_path
from tests.locator.test_run import MODEL, FakeSource, truth_run


def test_predict_interval_is_directional():
    acc = OdometerAccuracy(abs_error_m=1.0, over_rel=0.1, under_rel=0.05)
    lo, hi = predict_interval(100.0, 110.0, 200.0, acc)  # moved 200 m toward +chainage
    assert lo == 100.0 + 200.0 - (1.0 + 20.0) and hi == 110.0 + 200.0 + (1.0 + 10.0)
    lo, hi = predict_interval(100.0, 110.0, -200.0, acc)  # backward: over-read shortens it
    assert lo == 100.0 - 200.0 - (1.0 + 10.0) and hi == 110.0 - 200.0 + (1.0 + 20.0)
    lo, hi = motion_bound(0.0, 10.0, 2.0, OdometerAccuracy(1.0, 0.0, 0.0, 40.0))
    assert lo == -81.0 and hi == 91.0


def test_fuse_intervals_intersects_alarms_and_carries():
    f = fuse_intervals([0, 0, 0, 0], [100, 100, 100, 100], [50, 150, np.nan, 90],
                       [120, 170, np.nan, 95], [True, True, False, False])  # fmt: skip
    np.testing.assert_array_equal(f.lo_m, [50, 0, 0, 0])
    np.testing.assert_array_equal(f.hi_m, [100, 100, 100, 100])
    assert list(f.status) == [FusionStatus.FUSED, FusionStatus.CONFLICT, FusionStatus.ODOMETRY,
                              FusionStatus.ODOMETRY]  # fmt: skip


def test_run_fuses_and_the_fused_interval_holds_the_truth():
    path = straight_path(heading_deg=60.0, length_m=4000.0)
    truth = truth_run(n=30)
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    assert (ep["fusion"] == "fused").all()
    assert ((ep["fused_lo_m"] <= truth) & (truth <= ep["fused_hi_m"])).all()
    assert (ep["fused_hi_m"] - ep["fused_lo_m"] <= ep["hi_m"] - ep["lo_m"] + 1e-9).all()

    # satellites lost from epoch 10 on: the odometry carries the train, growing
    class Blind(FakeSource):
        def observe(self, k, rx):
            d = super().observe(k, rx)
            return d if k < 10 else d._replace(sats=(), sat_ecef_m=np.zeros((0, 3)),
                                               pseudorange_m=np.zeros(0))  # fmt: skip

    ep = run_locator(path, Blind(path, truth), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    tail = ep.iloc[10:]
    assert (tail["fusion"] == "odometry").all() and not tail["claim"].any()
    assert ((tail["fused_lo_m"] <= truth[10:]) & (truth[10:] <= tail["fused_hi_m"])).all()
    width = (tail["fused_hi_m"] - tail["fused_lo_m"]).to_numpy()
    assert np.all(np.diff(width) > 0)
    # the growth is the SUBSET-041 bound: 2 * 0.05 per metre travelled (15 m per epoch)
    np.testing.assert_allclose(np.diff(width), 2 * 0.05 * 15.0)
    np.testing.assert_allclose(tail["odo_since_anchor_m"], 15.0 * np.arange(1, 21))


def test_claim_outside_the_odometry_interval_is_an_alarm_not_a_reset():
    path = straight_path(heading_deg=60.0, length_m=4000.0)
    truth = truth_run(n=12)
    odo = truth - truth[0]
    odo = odo.copy()
    odo[6:] += 400.0  # the odometer jumps 400 m ahead
    ep = run_locator(path, FakeSource(path, truth, odometer_m=odo), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    bad = ep.iloc[6:]
    assert (bad["fusion"] == "conflict").all() and not bad["claim"].any()
    # the anchor stays at epoch 5: the odometry interval is the jumped one, not reset
    assert (bad["fused_lo_m"] > truth[6:]).all()


def test_estimate_filter_blends_by_inverse_variance():
    e, v = blend_estimate(10.0, 4.0, 14.0, 4.0)
    assert e == 12.0 and v == 2.0
    e, v = blend_estimate(10.0, 1.0, 14.0, 3.0)
    assert e == 11.0 and v == 0.75
    e, v = blend_estimate(10.0, np.nan, 14.0, 3.0)  # no prediction: the fix
    assert e == 14.0 and v == 3.0
    acc = OdometerAccuracy(abs_error_m=1.0, over_rel=0.03, under_rel=0.06)
    e, v = predict_estimate(100.0, 1.0, -50.0, acc, floor_m=0.1)
    assert e == 50.0 and v == pytest.approx(1.0 + (0.02 * 50.0) ** 2 + 0.01)


def test_fused_estimate_is_closer_than_the_fix():
    path = straight_path(heading_deg=60.0, length_m=4000.0)
    truth = truth_run(n=40)
    ep = run_locator(path, FakeSource(path, truth, seed=4), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none"))  # fmt: skip
    fix_err = np.abs(ep["chainage_m"] - truth)[10:]
    fused_err = np.abs(ep["fused_chainage_m"] - truth)[10:]
    assert fused_err.mean() < 0.7 * fix_err.mean()


def test_a_fix_whose_estimate_lies_outside_the_odometry_interval_is_an_alarm():
    # the claim [40, 140] meets the odometry interval [0, 100] but its estimate 120 does not
    f = fuse_intervals([0.0], [100.0], [40.0], [140.0], [True], gnss_est_m=[120.0])
    assert f.status[0] == FusionStatus.CONFLICT and f.lo_m[0] == 0.0 and f.hi_m[0] == 100.0
    f = fuse_intervals([0.0], [100.0], [40.0], [140.0], [True])  # the overlap rule alone
    assert f.status[0] == FusionStatus.FUSED
    path = straight_path(heading_deg=60.0, length_m=4000.0)
    truth = truth_run(n=12)
    odo = (truth - truth[0]).copy()
    odo[6:] += 14.0  # a 14 m jump: the prediction still meets the fix interval, not its estimate
    for rule, conflicts in (("estimate", True), ("overlap", False)):
        ep = run_locator(path, FakeSource(path, truth, odometer_m=odo), start_chainage_m=truth[0],
                         config=RunConfig(MODEL, trust="none", odometry_conflict=rule))  # fmt: skip
        assert (ep["fusion"].iloc[6] == "conflict") == conflicts, rule


def test_the_odometer_fixed_error_is_not_added_again_at_every_epoch():
    # a 2 m start (a balise) and satellite intervals of about 12 m that never tighten it: the
    # fused interval grows by the odometer's bounds since the start, once, not by 2 x 0.5 m per
    # epoch (which would reach the satellite width within ten epochs)
    path = straight_path(heading_deg=60.0, length_m=4000.0)
    truth = truth_run(n=30)
    acc = OdometerAccuracy(abs_error_m=0.5, over_rel=0.001, under_rel=0.001)
    ep = run_locator(path, FakeSource(path, truth), start_chainage_m=truth[0],
                     config=RunConfig(MODEL, trust="none", odometer=acc,
                                      start_uncertainty_m=1.0))  # fmt: skip
    width = (ep["fused_hi_m"] - ep["fused_lo_m"]).to_numpy()
    assert ((ep["fused_lo_m"] <= truth) & (truth <= ep["fused_hi_m"])).all()
    moved = truth - truth[0]
    assert np.all(width <= 2.0 + 2 * 0.5 + 2 * 0.001 * moved + 1e-9)
    assert (ep["hi_m"] - ep["lo_m"]).min() > 3 * width.max()  # the satellites are wider


def test_the_odometers_disputed_distance_keeps_a_blind_run_on_the_train():
    path = straight_path(heading_deg=60.0, length_m=4000.0)
    truth = truth_run(n=30)  # 15 m per epoch
    odo = truth - truth[0]
    # from epoch 10 the radar lost its echo and was believed: the odometer stands still,
    # while the wheel, which it overruled, ran on with the train (the disputed distance)
    stuck = np.where(np.arange(30) < 10, odo, odo[9])
    ahead = np.maximum(odo - stuck, 0.0)
    extra = np.column_stack([np.zeros(30), ahead])  # toward lower / higher chainage

    class Blind(FakeSource):  # and no satellites from epoch 10 (a tunnel)
        def __init__(self, *a, extra=None, **k):
            super().__init__(*a, **k)
            self.odometer_extra_m = extra

        def observe(self, k, rx):
            d = super().observe(k, rx)
            return d if k < 10 else d._replace(sats=(), sat_ecef_m=np.zeros((0, 3)),
                                               pseudorange_m=np.zeros(0))  # fmt: skip

    cfg = RunConfig(MODEL, trust="none")
    tail = slice(12, None)
    ep = run_locator(path, Blind(path, truth, odometer_m=stuck), start_chainage_m=truth[0],
                     config=cfg)  # fmt: skip
    assert (ep["fused_hi_m"].to_numpy()[tail] < truth[tail]).all()  # the failure, unseen
    ep = run_locator(path, Blind(path, truth, odometer_m=stuck, extra=extra),
                     start_chainage_m=truth[0], config=cfg)  # fmt: skip
    assert ((ep["fused_lo_m"] <= truth) & (truth <= ep["fused_hi_m"])).all()
    np.testing.assert_allclose(ep["odo_disputed_m"].to_numpy()[tail], ahead[tail])
