"""Balise lists: generation, round trip, bad files (locator.balises.balisefile)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from locator.balises.balisefile import BaliseFileError, BaliseList
from tests.locator._scene import straight_path


@pytest.fixture(scope="module")
def track():
    return straight_path(heading_deg=60.0, length_m=2000.0).track


def test_along_track_round_trip(tmp_path, track):
    bl = BaliseList.along_track(track, 100.0, 1000.0, 120.0)
    assert len(bl) == 8 and np.all(np.diff(bl.chainage_m) == 120.0)
    back = BaliseList.from_csv(bl.to_csv(tmp_path / "b.csv"), track)
    assert back.ids == bl.ids and back.telegram == bl.telegram
    np.testing.assert_array_equal(back.chainage_m, bl.chainage_m)
    np.testing.assert_array_equal(back.lat_deg, bl.lat_deg)
    assert back.q_reference.all()


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda df: df.drop(columns="telegram"), "missing columns"),
        (
            lambda df: df.assign(id=["A", "B", "C", "B", "E"]),
            r"line 5: id 'B' already used on line 3",
        ),
        (
            lambda df: df.assign(chainage_m=np.where(df.index == 4, 2500.0, df["chainage_m"])),
            r"line 6: balise .* off the track",
        ),
        (lambda df: df.iloc[[0, 2, 1, 3, 4]], r"line 4: balise .* does not follow"),
        (
            lambda df: df.assign(
                chainage_m=np.where(df.index == 2, df["chainage_m"] + 30.0, df["chainage_m"])
            ),
            r"line 4: balise .* coordinates are 30.0 m from the track",
        ),
        (
            lambda df: df.assign(h_m=np.where(df.index == 1, "x", df["h_m"].astype(str))),
            r"line 3: h_m is empty or not a number",
        ),
    ],
)
def test_bad_lists_name_the_line_and_the_fix(tmp_path, track, edit, match):
    bl = BaliseList.along_track(track, 100.0, 900.0, 200.0)
    p = tmp_path / "b.csv"
    bl.to_csv(p)
    edit(pd.read_csv(p)).to_csv(p, index=False)
    with pytest.raises(BaliseFileError, match=match) as exc:
        BaliseList.from_csv(p, track)
    assert str(p) in str(exc.value)
