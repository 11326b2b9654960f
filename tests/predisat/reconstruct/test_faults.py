"""Tests of the fault injection harness on hand-drawn scenes whose pixels are known."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.reconstruct.faults import (
    FAULT_CLASSES,
    LABEL_BUILDING,
    LABEL_GROUND,
    LABEL_NONE,
    LABEL_OTHER,
    LABEL_SKY,
    FaultRates,
    false_sky_stats,
    inject_faults,
)

H, W = 60, 80


def scene() -> tuple[np.ndarray, np.ndarray]:
    """Sky above row 30, ground below; a building (cols 10-49, top row 12), a mast 3 px wide
    (cols 60-62, top row 5); the top-right corner is not imaged."""
    lab = np.full((H, W), LABEL_SKY, np.int8)
    lab[30:] = LABEL_GROUND
    lab[12:30, 10:50] = LABEL_BUILDING
    lab[5:30, 60:63] = LABEL_OTHER
    lab[:4, 75:] = LABEL_NONE
    return lab == LABEL_SKY, lab


def only(kind: str) -> FaultRates:
    return FaultRates({kind: 1.0})


def test_false_sky_stats_by_hand() -> None:
    truth = np.zeros((150, 4), bool)
    truth[:75] = True
    pred = truth.copy()
    pred[75:76, 0] = True  # one row: under 1 % of the height
    pred[75:77, 1] = True  # two rows joined to the sky: unsafe
    pred[100:102, 2] = True  # two rows, not joined: unsafe, not joined
    st = false_sky_stats(pred, truth)
    assert st == {"false_sky_px": 5, "non_sky_px": 300, "unsafe_columns": 2,
                  "unsafe_joined_columns": 1, "columns": 4}  # fmt: skip


def test_no_rate_no_change_and_inputs_untouched() -> None:
    sky, lab = scene()
    before = sky.copy()
    out, faults = inject_faults([sky], [lab], ["left"], FaultRates(), seed=1)
    assert faults == []
    np.testing.assert_array_equal(out[0], sky)
    np.testing.assert_array_equal(sky, before)


@pytest.mark.parametrize("kind", FAULT_CLASSES)
def test_every_fault_only_adds_sky_in_imaged_pixels(kind: str) -> None:
    sky, lab = scene()
    for seed in range(5):
        out, faults = inject_faults([sky] * 3, [lab] * 3, ["left"] * 3, only(kind), seed)
        for m in out:
            assert (m >= sky).all()  # sky stays sky
            assert not (m & (lab == LABEL_NONE)).any()
        assert {f.kind for f in faults} <= {kind}
        # a drop may fall on sky alone (nothing to change); the others always find a target
        assert faults or kind == "lens_drop", f"{kind} put nothing in the scene (seed {seed})"


@pytest.mark.parametrize("kind,label", [("facade_band", LABEL_BUILDING),
                                        ("glass_mirror", LABEL_BUILDING),
                                        ("wet_ground", LABEL_GROUND)])  # fmt: skip
def test_scene_faults_take_their_class_only_from_the_skyline_down(kind: str, label: int) -> None:
    sky, lab = scene()
    for seed in range(5):
        out, _ = inject_faults([sky], [lab], ["left"], only(kind), seed)
        added = out[0] & ~sky
        assert added.any()
        assert (lab[added] == label).all()
        # joined to the sky above: each column's added pixels start at its skyline
        for c in np.flatnonzero(added.any(axis=0)):
            rows = np.flatnonzero(added[:, c])
            assert rows[0] == np.argmax(~sky[:, c])
            assert np.all(np.diff(rows) == 1)


def test_glass_reaches_the_foot_of_the_facade() -> None:
    sky, lab = scene()
    out, _ = inject_faults([sky], [lab], ["left"], only("glass_mirror"), 2)
    cols = np.flatnonzero((out[0] & ~sky).any(axis=0))
    assert cols.size and out[0][12:30, cols].all()


def test_thin_structures_are_lost_but_buildings_stay() -> None:
    sky, lab = scene()
    out, _ = inject_faults([sky], [lab], ["left"], only("thin_lost"), 0)
    assert out[0][5:30, 60:63].all()  # the 3 px mast is gone (seed 0 draws a kernel of 5-9 px)
    assert not out[0][12:30, 10:50].any()  # the building stays
    for seed in range(1, 6):
        out, _ = inject_faults([sky], [lab], ["left"], only("thin_lost"), seed)
        assert not out[0][12:30, 10:50].any()


def test_skyline_shift_moves_every_skyline_down_one_to_four_rows() -> None:
    sky, lab = scene()
    out, _ = inject_faults([sky], [lab], ["left"], only("skyline_shift"), 3)
    first = np.argmax(~sky, axis=0)
    first_new = np.argmax(~out[0], axis=0)
    shift = (first_new - first)[:75]  # the columns with a known top
    assert shift.min() == shift.max() and 1 <= shift.min() <= 4


def test_a_lens_drop_stays_on_one_camera_for_several_frames() -> None:
    sky = np.zeros((H, W), bool)
    lab = np.full((H, W), LABEL_OTHER, np.int8)
    n = 12
    out, faults = inject_faults([sky] * n, [lab] * n, ["left", "right"] * (n // 2),
                                FaultRates({"lens_drop": 1.0}), 0)  # fmt: skip
    left = [f.frame for f in faults if f.frame % 2 == 0]
    assert len(left) >= 3
    first = out[left[0]]
    # the same disc on the next frames of that camera, until it dries
    assert all(np.array_equal(out[i], first) for i in left[1:3])


def test_rates_are_checked_and_the_mix_sums_to_the_total() -> None:
    with pytest.raises(ValueError, match="unknown fault class"):
        FaultRates({"smudge": 0.1})
    with pytest.raises(ValueError, match="must lie in"):
        FaultRates({"thin_lost": 1.5})
    assert FaultRates.mix(0.4).total == pytest.approx(0.4)
    m = FaultRates.mix(0.4, whole_frame=0.04)
    assert m.rates["whole_frame"] == 0.04 and m.total == pytest.approx(0.44)
    with pytest.raises(ValueError, match="one entry per frame"):
        inject_faults([np.zeros((2, 2), bool)], [], ["left"], FaultRates())
