"""Fixes beside the track map (locator.workflow.check_track_offset): a trial's antenna 25-50 m
beside the map ran without a word, and 4.5 m beside it (a passing loop) made hazardous
misleading information with k = 2 on real stations."""

from __future__ import annotations

import numpy as np
import pytest

from locator.workflow import OFF_MAP_REFUSE_M, OFF_MAP_WARN_M, check_track_offset
from tests.locator._scene import straight_path


def _beside(offset_m: float, n: int = 30) -> np.ndarray:
    """Fixes every 20 m along the straight path (heading 60 deg), ``offset_m`` to its left,
    ECEF metres, with 0.5 m of noise."""
    path = straight_path(heading_deg=60.0, length_m=4000.0)
    s = 1000.0 + 20.0 * np.arange(n)
    x = path.ecef_at(s)
    t = path.tangent_ecef_at(s)
    up = x / np.linalg.norm(x, axis=1, keepdims=True)
    left = np.cross(up, t)
    noise = np.random.default_rng(1).normal(0.0, 0.5, (n, 3))
    return path, x + offset_m * left + noise


@pytest.mark.parametrize("offset_m", [0.0, 1.5, -2.0])
def test_fixes_on_the_map_pass(offset_m: float) -> None:
    path, fixes = _beside(offset_m)
    assert check_track_offset(path, fixes, "run.obs") is None


def test_fixes_beside_the_map_are_told_and_far_ones_refused() -> None:
    path, fixes = _beside(4.5)
    note = check_track_offset(path, fixes, "run.obs")
    assert note is not None and note.startswith("run.obs: the receiver's own fixes lie 4.")
    assert "left of" in note and "passing loop" in note
    path, fixes = _beside(-4.5)
    assert "right of" in (check_track_offset(path, fixes, "x") or "")
    path, fixes = _beside(30.0)
    with pytest.raises(ValueError, match=r"30\.\d m left of .*another track or line"):
        check_track_offset(path, fixes, "run.obs")
    assert OFF_MAP_WARN_M < 4.5 < OFF_MAP_REFUSE_M < 30.0
    # no usable fix: nothing to say
    assert check_track_offset(path, np.full((3, 3), np.nan), "x") is None
