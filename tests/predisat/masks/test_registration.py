"""Masks made on one map of a line, looked up on another: by position, widened by the maps'
disagreement. Line 144 as the demo's map (Infrabel's axis at 1 m) and as a 1.5 km excerpt of
the same track from Infrabel's network at 10 m (another chainage origin, positions metres
apart)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import predisat.masks.carry as carry
import predisat.masks.registration as registration
from predisat.masks.maskset import BinSource, MaskSet
from predisat.masks.registration import register_on_track
from predisat.track import TrackMap, demo_track, load_track

EXCERPT = Path(__file__).parents[2] / "data" / "track" / "network_gembloux.geojson"


@pytest.fixture(scope="module")
def maps() -> tuple[TrackMap, TrackMap]:
    return demo_track(), load_track(EXCERPT, where={"linecalfa": "144"})


def _sharp_masks(track: TrackMap, ch: np.ndarray, seed: int = 0) -> MaskSet:
    """Masks that change sharply from one position to the next, some bins ASSUMED."""
    rng = np.random.default_rng(seed)
    mask = rng.uniform(0.0, 70.0, (ch.size, 72)).astype(np.float32)
    source = np.where(rng.random(mask.shape) < 0.05, BinSource.ASSUMED, BinSource.OBSERVED)
    support = rng.integers(0, 6, mask.shape).astype(np.uint8)
    margin = rng.uniform(0.0, 2.0, mask.shape).astype(np.float32)
    return MaskSet.from_track(track, ch, mask, source=source.astype(np.uint8), margin_deg=margin,
                              support=support)  # fmt: skip


def _cell(m: MaskSet, chainage_m: np.ndarray) -> np.ndarray:
    return np.asarray(m.position_index(chainage_m)[0])


def test_every_place_gets_at_least_the_sky_the_masks_hold_there(maps) -> None:
    """Places every 0.5 m on either map: the masks looked up on the other map at the place's
    chainage there are never below the masks of the place (its cell on the map they were made
    on): mask, margin and the ASSUMED flag. Looked up by chainage, or re-registered without the
    widening, they are."""
    a, b = maps
    m = _sharp_masks(a, np.arange(400.0, 1701.0, 10.0))
    reg = register_on_track(m, b, "m", same_track=True)
    assert not reg.same_map and reg.shift_m > 250.0 and 1.0 < reg.offset_m < 15.0
    r = reg.masks
    assert r.provenance["registered_on"]["track"] == b.name
    # places on the masks' own map, and places on the other map
    s_a = np.arange(460.0, 1640.0, 0.5)
    lat, lon, _ = a.position_at(s_a)
    on_b = np.asarray(b.project(lat, lon).chainage_m)
    s_b = np.arange(float(r.chainage_m[5]), float(r.chainage_m[-5]), 0.5)
    lat_b, lon_b, _ = b.position_at(s_b)
    on_a = np.asarray(a.project(lat_b, lon_b).chainage_m)
    # places between the maps and a little beyond either (the train is on neither exactly)
    foot = np.asarray(b.position_at(on_b)[:2]).T
    here = np.asarray(a.position_at(s_a)[:2]).T
    t_off = np.random.default_rng(3).uniform(-0.3, 1.3, s_a.size)[:, None]
    x = here + t_off * (foot - here)
    x_a = np.asarray(a.project(x[:, 0], x[:, 1]).chainage_m)
    x_b = np.asarray(b.project(x[:, 0], x[:, 1]).chainage_m)
    for own, other in ((s_a, on_b), (on_a, s_b), (x_a, x_b)):
        want = _cell(m, own)
        got = _cell(r, other)
        need = m.effective_mask_deg[want]
        assert np.all(r.effective_mask_deg[got] >= need - 1e-5)
        assert np.all(r.source[got][m.source[want] == BinSource.ASSUMED] == BinSource.ASSUMED)
    # by chainage, the masks of places 300 m away; re-registered without widening, of the
    # neighbouring cell where the maps disagree
    by_chainage = np.clip(on_b, m.chainage_m[0], m.chainage_m[-1])
    assert (m.effective_mask_deg[_cell(m, by_chainage)] < m.effective_mask_deg[_cell(m, s_a)]
            ).any()  # fmt: skip


def test_without_the_widening_a_place_gets_a_neighbour_s_sky(maps, monkeypatch) -> None:
    a, b = maps
    m = _sharp_masks(a, np.arange(400.0, 1701.0, 10.0), seed=1)
    monkeypatch.setattr(registration, "_worst_over", lambda target, source, lo, hi: target)
    r = register_on_track(m, b, "m", same_track=True).masks
    s_a = np.arange(460.0, 1640.0, 0.5)
    lat, lon, _ = a.position_at(s_a)
    got = _cell(r, np.asarray(b.project(lat, lon).chainage_m))
    assert (r.effective_mask_deg[got] < m.effective_mask_deg[_cell(m, s_a)] - 1e-3).any()


def test_on_the_same_map_nothing_changes(maps) -> None:
    a, _ = maps
    m = _sharp_masks(a, np.arange(4000.0, 4500.0, 10.0))
    reg = register_on_track(m, a, "m")  # the default: nothing to say on the same map
    assert reg.same_map and reg.masks is m and reg.widen_m == 0.0
    assert "were made on track" in reg.describe("m", a.name)


def test_widening_keeps_the_weakest_support(maps) -> None:
    a, b = maps
    m = _sharp_masks(a, np.arange(400.0, 1701.0, 10.0), seed=2)
    r = register_on_track(m, b, "m", same_track=True).masks
    assert r.support is not None and m.support is not None
    assert r.n_pos == 2 * m.n_pos - 1  # a position added half-way between each two
    assert np.all(r.support[0::2] <= m.support)
    assert np.all(r.mask_el_deg[0::2] >= m.mask_el_deg)
    assert np.all(r.margin_deg[0::2] >= m.margin_deg)
    # the added positions take the worse of their two neighbours
    worse = np.maximum(m.effective_mask_deg[1:], m.effective_mask_deg[:-1])
    assert np.all(r.effective_mask_deg[1::2] >= worse - 1e-5)


def test_another_track_a_reversed_map_and_masks_past_the_map(maps) -> None:
    a, b = maps
    m = _sharp_masks(a, np.arange(400.0, 1701.0, 10.0))
    moved = TrackMap.from_latlon(b.lat_deg + 0.005, b.lon_deg, b.h_m, name="moved")
    with pytest.raises(ValueError, match=r"do not fit track 'moved'.*made on"):
        register_on_track(m, moved, "m.parquet")
    back = TrackMap.from_latlon(b.lat_deg[::-1], b.lon_deg[::-1], b.h_m[::-1], name="back")
    with pytest.raises(ValueError, match="runs the other way"):
        register_on_track(m, back, "m.parquet", same_track=True)  # 4.5 m apart: said
    # the excerpt starts near chainage 300 of the demo's map: positions before it are left out
    longer = _sharp_masks(a, np.arange(250.0, 1701.0, 10.0))
    reg = register_on_track(longer, b, "m", same_track=True)
    assert 3 <= reg.beyond <= 8 and reg.masks.n_pos == 2 * (longer.n_pos - reg.beyond) - 1
    assert "past the map's ends left out" in reg.describe("m", b.name)


def test_maps_at_an_angle_need_the_widening(monkeypatch) -> None:
    """Two straight maps of a line crossing at 8 deg (21 m apart at the ends, another
    chainage origin): places between and a little beyond them, looked up with
    :meth:`MaskSet.mask_at` (``+inf`` outside the coverage), get at least their sky on the
    masks' own map, to the coverage's ends; carrying the cells over without the places'
    reach off the map does not."""
    from predisat.geodesy import WGS84
    from tests.predisat.synth.test_world import straight_track

    a = straight_track(300.0, 60.0)
    mid_lat, mid_lon, _ = a.position_at(150.0)
    ends = []
    for az in (240.0 + 8.0, 60.0 + 8.0):  # B: A turned 8 deg about its middle, 40 m longer
        lo, la, _ = WGS84.fwd(mid_lon, mid_lat, az, 170.0)
        ends.append((la, lo))
    b = TrackMap.from_latlon(np.array([ends[0][0], ends[1][0]]),
                             np.array([ends[0][1], ends[1][1]]), 100.0, name="B")  # fmt: skip
    m = _sharp_masks(a, np.arange(20.0, 281.0, 10.0), seed=4)
    s_a = np.arange(5.0, 295.0, 0.05)
    here = np.asarray(a.position_at(s_a)[:2]).T
    on_b = np.asarray(b.project(here[:, 0], here[:, 1]).chainage_m)
    foot = np.asarray(b.position_at(on_b)[:2]).T
    t_off = np.random.default_rng(5).uniform(-0.3, 1.3, s_a.size)[:, None]
    x = here + t_off * (foot - here)
    x_a = np.asarray(a.project(x[:, 0], x[:, 1]).chainage_m)
    x_b = np.asarray(b.project(x[:, 0], x[:, 1]).chainage_m)
    az = np.arange(0.0, 360.0, 5.0)[None, :]

    def lower_anywhere() -> bool:
        r = register_on_track(m, b, "m", same_track=True).masks
        got = r.mask_at(x_b[:, None], az)
        own = m.mask_at(x_a[:, None], az)
        return bool((got < own - 1e-5).any())

    assert not lower_anywhere()
    # end positions a few centimetres to a metre from the next (frames at a standstill are
    # kept to the millimetre): the coverage still stops short of the places past the end
    bunched = np.concatenate([[20.0, 20.05, 21.0], np.arange(30.0, 271.0, 10.0),
                              [279.0, 279.97, 280.0]])  # fmt: skip
    m_end = _sharp_masks(a, bunched, seed=6)
    r_end = register_on_track(m_end, b, "m", same_track=True).masks
    got = r_end.mask_at(x_b[:, None], az)
    own = m_end.mask_at(x_a[:, None], az)
    assert not (got < own - 1e-5).any()
    with monkeypatch.context() as mp:  # without moving the ends: places past them get sky
        mp.setattr(registration, "_end_inside", lambda ch, limit: 0)
        mp.setattr(registration, "_moved_ends",
                   lambda masks, first, last, lo, hi: masks)  # fmt: skip
        r_open = register_on_track(m_end, b, "m", same_track=True).masks
        assert (r_open.mask_at(x_b[:, None], az) < own - 1e-5).any()
    monkeypatch.setattr(carry, "_reach_m", lambda off: np.zeros_like(off))
    monkeypatch.setattr(carry, "_WIDEN_SLACK_M", 0.0)
    assert lower_anywhere()


def test_uneven_masks_past_both_ends_of_a_shorter_map(maps) -> None:
    """A reviewer's case: masks over more than the map, unevenly spaced, looked up with
    ``mask_at`` all along the map (``+inf`` outside the coverage): positions past the ends
    give their sky to the places they reach, and no place gets less than on the masks' own
    map (a first version lost up to 64 deg near the ends)."""
    a, b = maps
    rng = np.random.default_rng(7)
    ch = np.sort(rng.uniform(200.0, 1900.0, 200))
    ch = ch[np.concatenate([[True], np.diff(ch) > 0.001])]
    m = _sharp_masks(a, ch, seed=8)
    reg = register_on_track(m, b, "m", same_track=True)
    assert reg.beyond > 0
    s_b = np.arange(0.0, b.length_m, 0.05)
    lat, lon, _ = b.position_at(s_b)
    s_a = np.asarray(a.project(lat, lon).chainage_m)
    az = np.arange(0.0, 360.0, 5.0)[None, :]
    got = reg.masks.mask_at(s_b[:, None], az)
    own = m.mask_at(s_a[:, None], az)
    assert np.all(got >= own - 1e-5)


def test_a_line_across_the_antimeridian_keeps_its_positions_on_the_line() -> None:
    """The added half-way positions averaged longitudes: between 179.9999 and -179.9999 one
    landed at longitude 0, 12,000 km away (a geometry review, 2026-12-06)."""
    from pyproj import Geod

    geod = Geod(ellps="WGS84")
    n = 401
    lon, lat, _ = geod.fwd(np.full(n, 179.99), np.full(n, -16.8), np.full(n, 90.0),
                           np.arange(n) * 5.0)  # fmt: skip
    a = TrackMap.from_latlon(lat, lon, 0.0, "A", tolerance_m=0.05)
    lon2, lat2, _ = geod.fwd(lon, lat, np.zeros(n), np.full(n, 0.8))  # 0.8 m north
    b = TrackMap.from_latlon(lat2, lon2, 0.0, "B", tolerance_m=0.05)
    s = np.arange(20.0, a.length_m - 20, 10.0)
    la, lo, h = a.position_at(s)
    assert lo.min() < -179.99 and lo.max() > 179.99  # the line crosses 180 deg
    m = MaskSet.from_arrays(s, la, lo, h + 4, a.heading_at(s), np.full((len(s), 72), 10.0),
                            provenance={"track": "A"})  # fmt: skip
    out = register_on_track(m, b, "test").masks
    # every position within metres of the line (pyproj's geodesic to the nearest vertex)
    near = np.array([
        geod.inv(np.full(n, lon_i), np.full(n, lat_i), lon2, lat2)[2].min()
        for lat_i, lon_i in zip(out.lat_deg, out.lon_deg, strict=True)
    ])  # fmt: skip
    assert near.max() < 5.0


def test_masks_beside_the_map_as_another_tracks_would_need_the_same_track_said(maps) -> None:
    """Two maps of line 144's track A lie 4.5 m apart: geometry cannot tell them from the two
    tracks of a double line, so the caller must say which it is."""
    from predisat.masks.registration import OTHER_TRACK_OFFSET_M, OtherTrackError

    a, b = maps
    m = _sharp_masks(a, np.arange(400.0, 1701.0, 10.0))
    with pytest.raises(OtherTrackError, match=r"lie 4\.\d m (left|right) of track .* "
                                              r"--masks-same-track"):  # fmt: skip
        register_on_track(m, b, "m")
    reg = register_on_track(m, b, "m", same_track=True)
    assert reg.median_offset_m > OTHER_TRACK_OFFSET_M
    assert reg.masks.provenance["registered_on"]["same_track_confirmed"] is True
    assert "taken as the same physical track, as asked" in reg.describe("m", b.name)
    # the same axis moved 1 m north (within two maps of one track) needs nothing
    lat, lon, h = a.position_at(np.arange(0.0, a.length_m, 5.0))
    shifted = TrackMap.from_latlon(lat + 1.0 / 111_200.0, lon, h)
    near = register_on_track(m, shifted, "m")
    assert 0.2 < near.median_offset_m < OTHER_TRACK_OFFSET_M


def _bent(track: TrackMap, lo_m: float, hi_m: float, aside_m: float) -> TrackMap:
    """``track`` with the stretch ``lo_m``-``hi_m`` moved ``aside_m`` to its left (cosine ramps
    of 100 m at both ends), as a branch or a passing loop's track would lie."""
    s = np.arange(0.0, track.length_m, 5.0)
    lat, lon, h = track.position_at(s)
    ramp = np.clip(np.minimum(s - (lo_m - 100.0), (hi_m + 100.0) - s) / 100.0, 0.0, 1.0)
    left = aside_m * 0.5 * (1.0 - np.cos(np.pi * ramp))
    hd = np.radians(track.heading_at(s))
    north, east = left * np.sin(hd), -left * np.cos(hd)
    lat2 = lat + north / 111_200.0
    lon2 = lon + east / (111_200.0 * np.cos(np.radians(lat)))
    return TrackMap.from_latlon(lat2, lon2, h, name="bent", tolerance_m=0.05)


def test_a_stretch_beside_the_map_needs_the_same_track_said(maps) -> None:
    """A user trial: masks that followed a branch up to 23 m aside over part of the stretch
    passed (median 0 m) and trusted 2.4 % blocked directions there. A stretch more than 3.5 m
    beside over 50 m is now refused, naming it; the same bend at 3 m is two maps of one
    track."""
    from predisat.masks.registration import OtherTrackError

    a, _ = maps
    m = _sharp_masks(a, np.arange(400.0, 2001.0, 10.0))
    with pytest.raises(OtherTrackError, match=r"chainages 9\d\d\.\d-14\d\d\.\d m lie more than "
                       r"3\.5 m beside track 'bent', up to 6\.\d m right of it"):  # fmt: skip
        register_on_track(m, _bent(a, 1000.0, 1400.0, 6.0), "m")
    reg = register_on_track(m, _bent(a, 1000.0, 1400.0, 6.0), "m", same_track=True)
    assert reg.median_offset_m < 1.75  # the median alone let it through
    register_on_track(m, _bent(a, 1000.0, 1400.0, 3.0), "m")
    register_on_track(m, _bent(a, 1000.0, 1000.0, 4.0), "m")  # beside over less than 50 m


def test_masks_that_name_this_map_but_disagree_with_it_are_refused(maps) -> None:
    """A user trial: masks whose provenance names the very map in use, their chainages 20 m
    off their positions on it, were re-registered by position with a warning; if the
    chainages were the right ones, 4.8 % false trust. The file contradicts its own map."""
    import dataclasses

    from predisat.track.network import track_key

    a, _ = maps
    m = _sharp_masks(a, np.arange(400.0, 1701.0, 10.0))
    own = dataclasses.replace(m, provenance={"track_key": track_key(a)})
    assert register_on_track(own, a, "m").same_map  # consistent: nothing to do
    shifted = dataclasses.replace(own, chainage_m=own.chainage_m + 20.0)
    with pytest.raises(ValueError, match=r"made on this very map .* disagree"):
        register_on_track(shifted, a, "m")
    # without the key (another tool's file) it is registered by position, as before
    plain = dataclasses.replace(shifted, provenance={})
    assert not register_on_track(plain, a, "m").same_map


def test_positions_too_coarse_to_tell_the_tracks_are_said_so_not_named_another_track():
    """A review (2026-12-07): plain GNSS positions (3-5 m, as the survey format allows)
    wandering 3 m aside fired "the survey train may have run on another track" in 11 of 20
    surveys of the right track; a survey stating such a doubt is told that its positions
    cannot tell the tracks apart, and to confirm its route."""
    from predisat.masks.registration import beside_track_notes

    rec = {"median_offset_m": 2.1, "side": "left", "max_offset_m": 5.2, "stretch_m": None}
    exact = beside_track_notes({"survey_beside_track": {**rec, "position_doubt_m": None}})
    coarse = beside_track_notes({"survey_beside_track": {**rec, "position_doubt_m": 4.0}})
    assert "may have run on another track" in exact[0]
    assert "cannot tell this track from one beside it" in coarse[0]
    assert "within the 4 m the survey states" in coarse[0] and "route" in coarse[0]
    assert beside_track_notes({}) == []
