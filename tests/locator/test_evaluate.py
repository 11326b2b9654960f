"""Tests of run scoring (locator.evaluate) on hand-made epoch tables."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from locator.evaluate import score_run, summarise


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
