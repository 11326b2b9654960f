"""Kilometre posts (predisat.track.posts): only posts running strictly one way along the
chainage map it to the line's kilometres; the others are dropped with a warning naming them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from pyproj import Geod

from predisat.track.map import TrackMap
from predisat.track.posts import KilometrePost, monotone_posts

GEOD = Geod(ellps="WGS84")


def P(chainage_m: float, km_m: float, label: str = "") -> KilometrePost:
    return KilometrePost(chainage_m, km_m, label)


@pytest.mark.parametrize(
    ("posts", "kept", "named"),
    [
        # strictly increasing: all kept, no warning
        ([P(0, 10_000), P(1000, 11_000), P(2000, 12_000)], [10_000, 11_000, 12_000], []),
        # decreasing along the chainage (chainage reversed against the posts): all kept
        ([P(0, 12_000), P(1000, 11_000), P(2000, 10_000)], [12_000, 11_000, 10_000], []),
        # the OpenStreetMap case: one milestone twice, 5 cm apart (mapped on both tracks):
        # one post (both were dropped, and the line lost its only kilometre, a user trial)
        ([P(54_202.62, 80_000), P(54_202.68, 80_000)], [80_000], []),
        ([P(53_202.6, 79_000), P(54_202.62, 80_000), P(54_202.68, 80_000)], [79_000, 80_000],
         []),
        # the same kilometre 3 m apart is not one milestone: both dropped, said
        ([P(54_202.6, 80_000), P(54_205.6, 80_000)], [], ["km 80.000", "54.203"]),
        # one post out of order: it and its neighbour go, the rest stays
        ([P(0, 10_000), P(1000, 11_000), P(2000, 10_500, "X"), P(3000, 13_000)],
         [10_000, 13_000], ["km 11.000", "km 10.500 (X)"]),
        # two posts at one chainage with different kilometres
        ([P(0, 10_000), P(500, 10_500), P(500, 10_600), P(2000, 12_000)],
         [10_000, 12_000], ["km 10.500", "km 10.600"]),
    ],
)  # fmt: skip
def test_monotone_posts_drops_the_posts_that_do_not_run_one_way(
    posts: list[KilometrePost], kept: list[float], named: list[str]
) -> None:
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = monotone_posts(posts[::-1], "the file")  # any order in, chainage order out
    assert [p.km_m for p in out] == kept
    if named:
        (w,) = caught
        text = str(w.message)
        assert text.startswith("the file: kilometre posts") and "correct or remove" in text
        assert all(n in text for n in named), text
    else:
        assert not caught


def _line_with_posts(path: Path, posts_km: list[float], at_m: list[float]) -> Path:
    """A 2 km straight line going east at 50.5 N with kilometre posts at given distances."""
    lon1, lat1, _ = GEOD.fwd(4.7, 50.5, 90.0, 2000.0)
    pts = GEOD.npts(4.7, 50.5, lon1, lat1, 19)
    coords = [[4.7, 50.5], *[[x, y] for x, y in pts], [lon1, lat1]]
    plon, plat, _ = GEOD.fwd([4.7] * len(at_m), [50.5] * len(at_m), [90.0] * len(at_m), at_m)
    features = [{"type": "Feature", "properties": {},
                 "geometry": {"type": "LineString", "coordinates": coords}}]
    features += [{"type": "Feature", "properties": {"railway": "milestone",
                                                    "railway:position": f"{km:.3f}"},
                  "geometry": {"type": "Point", "coordinates": [x, y]}}
                 for km, x, y in zip(posts_km, plon, plat, strict=True)]  # fmt: skip
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    return path


def test_a_duplicated_milestone_is_one_post_not_a_flat_line(tmp_path: Path) -> None:
    """One milestone mapped twice 5 cm apart: once "km 80.000" over the whole line
    (interpolated flat between the two), then no kilometre at all (both dropped); it is one
    post, labelling the kilometre around it (a user trial)."""
    import warnings

    from predisat.availability.report import _km_label

    path = _line_with_posts(tmp_path / "dup.geojson", [80.0, 80.0], [1500.0, 1500.05])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tm = TrackMap.from_geojson(path)
    assert [p.km_m for p in tm.kilometre_posts] == [80_000.0]
    km = tm.kilometre_at([100.0, 1000.0, 1900.0])
    assert np.isnan(km[0])  # not the whole line
    np.testing.assert_allclose(km[1:], [79_500.0, 80_400.0], atol=1.0)
    assert _km_label(tm, 100.0) == "chainage 0.100 km"


def test_good_posts_beside_a_bad_one_still_label_the_line(tmp_path: Path) -> None:
    path = _line_with_posts(tmp_path / "rev.geojson", [10.0, 11.0, 10.5, 12.0],
                            [0.0, 1000.0, 1500.0, 2000.0])  # fmt: skip
    with pytest.warns(UserWarning, match=r"km 11\.000 .*km 10\.500"):
        tm = TrackMap.from_geojson(path)
    assert [p.km_m for p in tm.kilometre_posts] == [10_000.0, 12_000.0]
    assert tm.kilometre_at(1000.0) == pytest.approx(11_000.0, abs=1.0)
    # the map's own copies keep the rule (with_metadata, the constructor)
    with pytest.warns(UserWarning, match=r"track 'rev': kilometre posts km 10\.000 .*km 9\.000"):
        tm2 = tm.with_metadata(kilometre_posts=[*tm.kilometre_posts, P(1000.0, 9000.0)])
    assert [p.km_m for p in tm2.kilometre_posts] == [12_000.0]


def test_a_kilometre_equation_leaves_the_kilometres_between_its_posts_empty(
    tmp_path: Path,
) -> None:
    """The line's kilometres jump from 1.0 to 20.0 between the posts at 1000 and 1500 m (a
    line change): interpolated across, km 10.5 was said at 1250 m where the line's is 1.25 or
    20.0 (a GIS user trial)."""
    path = _line_with_posts(tmp_path / "eq.geojson", [0.0, 0.5, 1.0, 20.0, 20.5],
                            [0.0, 500.0, 1000.0, 1500.0, 2000.0])  # fmt: skip
    with pytest.warns(UserWarning, match=r"posts at km 1\.000 \(chainage 1000 m\) and km "
                      r"20\.000 \(1500 m\) do not follow the track"):  # fmt: skip
        tm = TrackMap.from_geojson(path)
    km = tm.kilometre_at([250.0, 990.0, 1250.0, 1600.0, 1750.0])
    np.testing.assert_allclose(km[[0, 1, 3, 4]], [250.0, 990.0, 20_100.0, 20_250.0], atol=1.0)
    assert np.isnan(km[2])
    # far beyond the outer posts nothing is said either (posts may have been dropped there)
    assert np.isnan(tm.kilometre_at(-1500.0)) and np.isfinite(tm.kilometre_at(-500.0))


def test_a_single_post_labels_one_kilometre_around_it(tmp_path: Path) -> None:
    """One post left: its kilometres were extrapolated 9 km away (a re-run of the GIS trial)."""
    tm = TrackMap.from_geojson(_line_with_posts(tmp_path / "one.geojson", [12.0], [200.0]))
    km = tm.kilometre_at([0.0, 1100.0, 1300.0])
    np.testing.assert_allclose(km[:2], [11_800.0, 12_900.0], atol=1.0)
    assert np.isnan(km[2])
