"""Masks checked against the train's antenna height (predisat.masks.antenna)."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.masks.antenna import (
    AntennaHeightError,
    check_antenna_height,
    masks_antenna_height_m,
)
from predisat.masks.maskset import MaskSet
from predisat.synth.truth import true_masks
from predisat.track import demo_track
from tests.predisat.reconstruct.test_carving import street_world


def test_seen_from_lower_down_the_obstacles_stand_higher() -> None:
    """The rule's ground, by ray casting: the true masks of a street (facades 5 m away) from
    3.0 m are nowhere below, and mostly above, those from 4.0 m; from 5.0 m nowhere above.
    (Without the catenary: its wires, centimetres thick, are hit or missed by the caster's
    sub-rays depending on the distance, not on the rule.)"""
    world = street_world([], catenary=False, seed=1)
    s = np.array([300.0, 450.0])
    at = {h: true_masks(world, s, h, az_step_deg=2.0).mask_el_deg for h in (3.0, 4.0, 5.0)}
    assert np.all(at[3.0] >= at[4.0] - 1e-6) and np.mean(at[3.0] - at[4.0]) > 1.0  # 1.86 deg
    assert np.all(at[5.0] <= at[4.0] + 1e-6)


def _masks(provenance: dict) -> MaskSet:
    c = np.arange(0.0, 101.0, 10.0)
    return MaskSet.from_track(demo_track(), c, np.zeros((len(c), 360)), provenance=provenance)


def test_masks_for_a_higher_antenna_are_refused_for_a_lower_one_said() -> None:
    masks = _masks({"antenna_height_m": 4.0})
    assert masks_antenna_height_m(masks) == 4.0
    assert check_antenna_height(masks, 4.1, "masks m.parquet") is None
    with pytest.raises(AntennaHeightError, match=r"masks m\.parquet were made for an antenna 4 m "
                       r"above the track axis, the train's is at 3\.5 m.*--antenna-height 3\.5"):
        check_antenna_height(masks, 3.5, "masks m.parquet")
    note = check_antenna_height(masks, 4.5, "masks m.parquet")
    assert note is not None and "safe side" in note
    unknown = _masks({})
    assert masks_antenna_height_m(unknown) is None
    note = check_antenna_height(unknown, 3.0, "masks x")
    assert note is not None and "state no antenna height" in note


def test_the_highest_statement_counts_old_files_and_merges_included() -> None:
    """A review: masks of a 3.0 m survey made before 2026-12-06 say 3.0 m but were carved at
    4.0 m (params.reconstruction); 5.0 m masks merged into 3.0 m ones kept 3.0 m. Both passed
    the check for a 3.0 m train."""
    from predisat.masks.merge import merge_worst_case

    old = _masks({"antenna_height_m": 3.0, "params": {"reconstruction": {"antenna_height_m": 4.0}}})
    assert masks_antenna_height_m(old) == 4.0
    with pytest.raises(AntennaHeightError):
        check_antenna_height(old, 3.0, "old masks")
    base = _masks({"antenna_height_m": 3.0})
    other = _masks({"antenna_height_m": 5.0})
    merged = merge_worst_case(base, [other], demo_track(), same_track=True).masks
    assert masks_antenna_height_m(merged) == 5.0
    with pytest.raises(AntennaHeightError):
        check_antenna_height(merged, 3.0, "merged masks")
