"""Tests of run scoring (locator.evaluate) on hand-made epoch tables."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from locator.evaluate import (
    STANFORD_REGIONS,
    score_run,
    stanford_counts,
    stanford_points,
    summarise,
)


def table() -> pd.DataFrame:
    # five epochs: inside+claim, outside+claim (HMI), outside+no claim (MI), no fix, inside+claim
    return pd.DataFrame(
        {
            "chainage_m": [100.0, 130.0, 90.0, np.nan, 102.0],
            "lo_m": [90.0, 120.0, 80.0, np.nan, 95.0],
            "hi_m": [110.0, 140.0, 95.0, np.nan, 125.0],
            "length_m": [20.0, 20.0, 15.0, np.nan, 30.0],
            "wls_chainage_m": [101.0, 129.0, 91.0, np.nan, 100.0],
            "claim": [True, True, False, False, True],
            "claim_fix": [True, True, True, False, True],
            "mode": ["three_pairs", "three_pairs", "all_pairs", "none", "all_pairs"],
        }
    )


def test_score_marks_outcomes():
    truth = np.array([101.0, 100.0, 100.0, 100.0, 100.0])
    sc = score_run(table(), truth)
    assert sc["inside"].tolist() == [True, False, False, False, True]
    assert sc["hmi"].tolist() == [False, True, False, False, False]
    # epoch 2 was claimed by the fix, then voided by a later check: fix-level HMI only
    assert sc["hmi_fix"].tolist() == [False, True, True, False, False]
    assert sc["mi"].tolist() == [False, False, True, False, False]
    assert np.allclose(sc["error_m"], [-1.0, 30.0, -10.0, np.nan, 2.0], equal_nan=True)
    assert "truth_m" not in table()  # the input is not modified


def test_summary_figures():
    sc = score_run(table(), np.array([101.0, 100.0, 100.0, 100.0, 100.0]))
    s = summarise(sc)
    assert s["epochs"] == 5 and s["claim_share"] == pytest.approx(0.6)
    assert s["mode_three_pairs_share"] == pytest.approx(0.4)
    assert s["mode_none_share"] == pytest.approx(0.2)
    assert s["length_median_m"] == pytest.approx(np.median([20.0, 20.0, 30.0]))
    assert s["length_max_m"] == 30.0
    assert s["abs_error_median_m"] == pytest.approx(np.median([1.0, 30.0, 10.0, 2.0]))
    assert (s["hmi"], s["hmi_fix"], s["mi"]) == (1, 2, 1)
    assert s["inside_share"] == pytest.approx(2 / 3)


def test_truth_length_is_checked():
    with pytest.raises(ValueError, match="one true chainage per epoch"):
        score_run(table(), np.zeros(3))


def test_claim_losses_count_each_epoch_once_under_its_first_cause():
    from locator.evaluate import claim_losses

    epochs = pd.DataFrame({
        "claim": [True, False, False, False, False, False, False, False],
        "flag_names": ["", "NO_SAFETY_CLAIM|TOO_FEW", "NO_SAFETY_CLAIM|EXCLUDED|FAULT_DETECTED",
                       "NO_SAFETY_CLAIM|FAULT_DETECTED|INCONSISTENT_PAIRS", "NO_SAFETY_CLAIM",
                       "NO_SAFETY_CLAIM|HEADING_FAIL", "ODOMETRY_CONFLICT", "BLUNT"],
        "n_used": [6, 1, 5, 6, 3, 6, 6, 6],
    })  # fmt: skip
    losses = claim_losses(epochs)
    assert sum(losses.values()) == pytest.approx(7 / 8)  # every lost epoch once
    assert next(iter(losses)).startswith("fault detected")  # 2 of 8, largest first
    assert losses[next(k for k in losses if k.startswith("fault detected"))] == 2 / 8
    assert losses["fewer than 2 trusted satellites"] == 1 / 8
    assert losses["2-3 satellites (a fix without claim)"] == 1 / 8
    assert losses["heading check failed"] == 1 / 8
    assert losses["interval missing the odometry prediction"] == 1 / 8
    assert losses["other"] == 1 / 8
    assert claim_losses(epochs.iloc[:1]) == {}
    # partitioned trust without a claimed stretch is named first: the row's fix is one
    # stretch's, whose own flags (2-3 satellites, an ambiguous pair) do not explain the epoch
    parts = pd.DataFrame({"claim": [False, False, False, False],
                          "flag_names": ["NO_SAFETY_CLAIM|NO_STRETCH_CLAIM"] * 2
                          + ["NO_SAFETY_CLAIM|AMBIGUOUS|NO_STRETCH_CLAIM", "NO_SAFETY_CLAIM"],
                          "n_used": [7, 3, 7, 3]})  # fmt: skip
    losses = claim_losses(parts)
    stretch = next(k for k in losses if "no stretch" in k)
    assert losses[stretch] == 3 / 4
    assert losses["2-3 satellites (a fix without claim)"] == 1 / 4


def test_exclusions_collect_satellites_per_reason():
    from locator.evaluate import exclusions

    epochs = pd.DataFrame({"excluded": [
        "G03:below the horizon G08:below_mask", "", "G08:fde E11:NO_DATA G03:below the horizon",
        "R07:no broadcast group delay for C1P",
    ]})  # fmt: skip
    assert exclusions(epochs) == {
        "below the horizon": {"G03"}, "below_mask": {"G08"}, "fde": {"G08"},
        "NO_DATA": {"E11"}, "no broadcast group delay for C1P": {"R07"},
    }  # fmt: skip


def _random_scored(seed: int, n: int = 4000) -> pd.DataFrame:
    """Random epochs: estimates inside asymmetric intervals, truths around them, random
    claims, some epochs without an estimate or with an unbounded interval."""
    rng = np.random.default_rng(seed)
    est = rng.uniform(1000.0, 5000.0, n)
    lo = est - rng.uniform(0.5, 60.0, n)
    hi = est + rng.uniform(0.5, 60.0, n)
    truth = est + rng.standard_t(3, n) * 15.0
    est[rng.random(n) < 0.03] = np.nan
    hi[rng.random(n) < 0.02] = np.inf
    ep = pd.DataFrame({"chainage_m": est, "lo_m": lo, "hi_m": hi, "length_m": hi - lo,
                       "wls_chainage_m": est, "claim": rng.random(n) < 0.7,
                       "claim_fix": True, "mode": "three_pairs"})  # fmt: skip
    return score_run(ep, truth)


def test_stanford_counts_from_containment():
    """The diagram's regions (|error| against the half-interval toward the truth) counted
    independently: the truth inside or outside [lo, hi], claimed or not."""
    sc = _random_scored(1)
    est, lo, hi = (sc[c].to_numpy(float) for c in ("chainage_m", "lo_m", "hi_m"))
    truth, claim = sc["truth_m"].to_numpy(float), sc["claim"].to_numpy(bool)
    has = np.isfinite(est) & np.isfinite(lo) & np.isfinite(hi)
    out = (truth < lo) | (truth > hi)
    want = {
        "normal": int((has & claim & ~out).sum()),
        "hmi": int((has & claim & out).sum()),
        "unavailable": int((has & ~claim & ~out).sum()),
        "mi": int((has & ~claim & out).sum()),
        "no_interval": int((~has).sum()),
    }
    got = stanford_counts(sc)
    assert list(got) == list(STANFORD_REGIONS)
    assert got == want
    assert min(want.values()) > 20  # every region is exercised
    assert got["hmi"] == sc.loc[has, "hmi"].sum()  # score_run's HMI, epochs with an estimate
    s = summarise(sc)
    assert s["stanford_hmi"] == want["hmi"] and s["stanford_mi"] == want["mi"]


def test_stanford_points_protection_level_and_alert_limit():
    # truth below the estimate: protection = est - lo; above: hi - est
    ep = pd.DataFrame({"chainage_m": [100.0, 100.0, 100.0, 100.0], "lo_m": [90.0, 95.0, 40.0, 90.0],
                       "hi_m": [130.0, 101.0, 160.0, 130.0], "length_m": 0.0,
                       "wls_chainage_m": 100.0, "claim": [True, True, True, False],
                       "claim_fix": True, "mode": "three_pairs"})  # fmt: skip
    sc = score_run(ep, np.array([92.0, 103.0, 150.0, 80.0]))
    pts = stanford_points(sc)
    np.testing.assert_allclose(pts["abs_error_m"], [8.0, 3.0, 50.0, 20.0])
    np.testing.assert_allclose(pts["protection_m"], [10.0, 1.0, 60.0, 10.0])
    assert pts["region"].tolist() == ["normal", "hmi", "normal", "mi"]
    # a 50 m alert limit: the 60 m protection level is unavailable although claimed
    assert stanford_points(sc, alert_limit_m=50.0)["region"].tolist() == [
        "normal", "hmi", "unavailable", "mi"]  # fmt: skip
    with pytest.raises(ValueError, match="alert_limit_m"):
        stanford_points(sc, alert_limit_m=0.0)
    with pytest.raises(ValueError, match="score_run"):
        stanford_points(ep)
