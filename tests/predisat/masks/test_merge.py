"""Masks of a passing loop merged worst-case onto the main track: a train on the loop, located
at its foot point on the main track, gets at least the loop's sky; elsewhere nothing changes.

The loop is laid 4.5 m beside the demo line's axis (tapered over 60 m at its switches); places
on it are checked through the main map's projection and each mask set's own cells, not through
the merge's code."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from predisat.cli.app import main as predisat_main
from predisat.masks.fileformat import read_masks, write_masks
from predisat.masks.maskset import BinSource, MaskSet
from predisat.masks.merge import merge_worst_case
from predisat.masks.registration import OtherTrackError
from predisat.track import TrackMap, demo_track

LOOP_M = (800.0, 1200.0)


def _beside(main: TrackMap, lo_m: float, hi_m: float, offset_m: float, taper_m: float = 60.0,
            name: str = "loop", reverse: bool = False) -> TrackMap:  # fmt: skip
    s = np.arange(lo_m, hi_m + 1e-9, 2.0)
    d = offset_m * np.clip(np.minimum(s - lo_m, hi_m - s) / taper_m, 0.0, 1.0) if taper_m else (
        np.full(s.size, offset_m))  # fmt: skip
    enu = np.asarray(main.enu_at(s), float)
    hd = np.radians(np.asarray(main.heading_at(s), float))
    left = np.column_stack([-np.cos(hd), np.sin(hd), np.zeros_like(hd)])
    lat, lon, h = (np.asarray(v) for v in main.frame.to_geodetic(enu + d[:, None] * left))
    if reverse:
        lat, lon, h = lat[::-1], lon[::-1], h[::-1]
    return TrackMap.from_latlon(lat, lon, h, name=name, tolerance_m=0.05)


def _masks(track: TrackMap, ch: np.ndarray, seed: int, top: float) -> MaskSet:
    rng = np.random.default_rng(seed)
    mask = rng.uniform(0.0, top, (ch.size, 72)).astype(np.float32)
    source = np.where(rng.random(mask.shape) < 0.05, BinSource.ASSUMED,
                      rng.integers(0, 2, mask.shape)).astype(np.uint8)  # fmt: skip
    return MaskSet.from_track(
        track, ch, mask, source=source, margin_deg=rng.uniform(0, 2, mask.shape).astype(
            np.float32), support=rng.integers(0, 6, mask.shape).astype(np.uint8),
        provenance={"track": track.name},
    )  # fmt: skip


@pytest.fixture(scope="module")
def scene() -> tuple[TrackMap, TrackMap, MaskSet, MaskSet]:
    main = demo_track()
    loop = _beside(main, *LOOP_M, 4.5)
    m_main = _masks(main, np.arange(500.0, 1501.0, 10.0), 1, 20.0)
    m_loop = _masks(loop, np.arange(3.0, loop.length_m - 2.0, 10.0), 2, 60.0)
    return main, loop, m_main, m_loop


def _loop_places(loop: TrackMap, masks: MaskSet) -> tuple[np.ndarray, np.ndarray]:
    """Places every 0.5 m over the loop masks' coverage, and their loop cells."""
    b = masks.cell_bounds_m
    s = np.arange(b[0] + 0.01, b[-1] - 0.01, 0.5)
    return s, np.asarray(masks.position_index(s)[0])


def _foot(main: TrackMap, loop: TrackMap, s: np.ndarray) -> np.ndarray:
    lat, lon, _ = loop.position_at(s)
    return np.asarray(main.project(lat, lon).chainage_m, float)


def test_a_train_on_the_loop_gets_at_least_the_loop_s_sky(scene) -> None:
    """Every place on the loop, looked up at its foot point on the main track: the merged masks
    are never below the loop's masks of the place (mask, margin, ASSUMED, support), nor below
    the main track's own; the main track's masks alone are below them at many places."""
    main, loop, m_main, m_loop = scene
    res = merge_worst_case(m_main, [m_loop], main, labels=["loop.parquet"])
    m = res.masks
    s, own = _loop_places(loop, m_loop)
    at = np.asarray(m.position_index(_foot(main, loop, s))[0])
    need = m_loop.effective_mask_deg[own]
    assert np.all(m.effective_mask_deg[at] >= need - 1e-5)
    assert np.all(m.mask_el_deg[at] >= m_loop.mask_el_deg[own])
    assert np.all(m.source[at][m_loop.source[own] == BinSource.ASSUMED] == BinSource.ASSUMED)
    assert np.all(m.support[at] <= m_loop.support[own])
    # never below the main track's own anywhere, and its ASSUMED bins stay ASSUMED
    assert np.all(m.effective_mask_deg >= m_main.effective_mask_deg - 1e-6)
    assert np.all(m.source[m_main.source == BinSource.ASSUMED] == BinSource.ASSUMED)
    # the main track's masks alone do not bound the loop's sky
    base_at = np.asarray(m_main.position_index(_foot(main, loop, s))[0])
    assert (m_main.effective_mask_deg[base_at] < need - 1.0).mean() > 0.5
    # a raised bin carries the flag of the loop's bin that raised it
    raised = m.mask_el_deg > m_main.mask_el_deg
    assert raised.any() and np.isin(m.source[raised], list(BinSource)).all()
    t = res.tracks[0]
    assert t.label == "loop.parquet" and t.made_on == "loop" and t.positions_left_out == 0
    assert t.positions_used == m_loop.n_pos and 4.0 < t.median_offset_m < 4.6
    assert t.bins_raised == int(((m.effective_mask_deg - m_main.effective_mask_deg) > 0).sum())
    assert "4.5 m beside" in t.describe()
    prov = m.provenance["merged_worst_case"]
    assert prov[0]["masks"] == "loop.parquet" and prov[0]["positions_used"] == m_loop.n_pos


def test_elsewhere_the_masks_are_unchanged_bit_for_bit(scene) -> None:
    main, _, m_main, m_loop = scene
    m = merge_worst_case(m_main, [m_loop], main).masks
    lo, hi = LOOP_M
    far = (m_main.cell_bounds_m[1:] < lo - 10.0) | (m_main.cell_bounds_m[:-1] > hi + 10.0)
    assert far.sum() > 40
    for attr in ("mask_el_deg", "margin_deg", "source", "support"):
        assert np.array_equal(getattr(m, attr)[far], getattr(m_main, attr)[far]), attr
    assert np.array_equal(m.chainage_m, m_main.chainage_m)
    # the inputs are left as they were (rebuilt alike; its creation time aside: a loaded run
    # builds it in another second)
    again = _masks(main, np.arange(500.0, 1501.0, 10.0), 1, 20.0)
    stamp = {"created_utc": m_main.provenance.get("created_utc")}
    assert m_main.equals(dataclasses.replace(again, provenance={**again.provenance, **stamp}))


def test_a_loop_surveyed_the_other_way_bounds_the_same_places(scene) -> None:
    main, _, m_main, _ = scene
    back = _beside(main, *LOOP_M, 4.5, name="loop back", reverse=True)
    m_back = _masks(back, np.arange(4.0, back.length_m - 2.0, 10.0), 3, 60.0)
    m = merge_worst_case(m_main, [m_back], main).masks
    s, own = _loop_places(back, m_back)
    at = np.asarray(m.position_index(_foot(main, back, s))[0])
    assert np.all(m.effective_mask_deg[at] >= m_back.effective_mask_deg[own] - 1e-5)


def test_two_loops_and_a_far_siding(scene) -> None:
    """Two loops on either side both bound; a siding 40 m away is left out and said."""
    main, loop, m_main, m_loop = scene
    right = _beside(main, 600.0, 900.0, -5.0, name="right loop")
    m_right = _masks(right, np.arange(2.0, right.length_m - 2.0, 10.0), 4, 50.0)
    siding = _beside(main, 1000.0, 1300.0, 40.0, taper_m=0.0, name="siding")
    m_siding = _masks(siding, np.arange(2.0, siding.length_m - 2.0, 10.0), 5, 80.0)
    res = merge_worst_case(m_main, [m_loop, m_right, m_siding], main)
    for trk, ms in ((loop, m_loop), (right, m_right)):
        s, own = _loop_places(trk, ms)
        at = np.asarray(res.masks.position_index(_foot(main, trk, s))[0])
        assert np.all(res.masks.effective_mask_deg[at] >= ms.effective_mask_deg[own] - 1e-5)
    far = res.tracks[2]
    assert far.positions_used == 0 and far.positions_left_out == m_siding.n_pos
    assert far.bins_raised == 0 and "nothing merged" in far.describe()
    alone = merge_worst_case(m_main, [m_loop, m_right], main).masks
    assert np.array_equal(alone.mask_el_deg, res.masks.mask_el_deg)


def test_refusals_name_the_set_and_the_fix(scene) -> None:
    main, loop, m_main, m_loop = scene
    with pytest.raises(ValueError, match="others is empty"):
        merge_worst_case(m_main, [], main)
    coarse = MaskSet.from_track(loop, m_loop.chainage_m, np.zeros((m_loop.n_pos, 36)))
    with pytest.raises(ValueError, match=r"other 1.*36 azimuth bins.*same azimuth step"):
        merge_worst_case(m_main, [coarse], main)
    one = MaskSet.from_track(loop, m_loop.chainage_m[:1], np.zeros((1, 72)))
    with pytest.raises(ValueError, match="single position"):
        merge_worst_case(m_main, [one], main)
    with pytest.raises(ValueError, match="max_offset_m"):
        merge_worst_case(m_main, [m_loop], main, max_offset_m=float("nan"))
    # the followed track's masks must be its own: the loop's are refused as another track's
    whole = _beside(main, 500.0, 1500.0, 4.5, taper_m=0.0, name="beside")
    beside = _masks(whole, np.arange(10.0, 990.0, 10.0), 6, 20.0)
    with pytest.raises(OtherTrackError, match=r"beside|left of"):
        merge_worst_case(beside, [m_loop], main)
    assert merge_worst_case(beside, [m_loop], main, same_track=True).masks.n_pos > 0


def test_the_command_writes_the_merged_file_and_keeps_its_inputs(scene, tmp_path: Path,
                                                                 capsys) -> None:  # fmt: skip
    main, _, m_main, m_loop = scene
    a = write_masks(m_main, tmp_path / "main.parquet")
    b = write_masks(m_loop, tmp_path / "loop.parquet")
    out = tmp_path / "merged" / "masks.parquet"
    assert predisat_main(["merge", str(a), "--other", str(b), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "loop.parquet (" in text and "bins raised" in text and str(out) in text
    got = read_masks(out)
    want = merge_worst_case(read_masks(a), [read_masks(b)], main).masks
    assert np.array_equal(got.mask_el_deg, want.mask_el_deg)
    assert np.array_equal(got.source, want.source)
    assert got.provenance["merged_worst_case"][0]["masks"] == str(b)
    # the output may not overwrite an input
    before = a.read_bytes()
    assert predisat_main(["merge", str(a), "--other", str(b), "--out", str(a)]) == 2
    assert "one of the mask files merged" in capsys.readouterr().err
    assert a.read_bytes() == before


def test_reports_say_the_masks_are_a_worst_case(scene) -> None:
    from predisat.masks.merge import merged_tracks_note

    main, _, m_main, m_loop = scene
    assert merged_tracks_note(m_main, "main.parquet") is None
    m = merge_worst_case(m_main, [m_loop], main, labels=["loop.parquet"]).masks
    note = merged_tracks_note(m, "merged.parquet")
    assert note is not None and "loop.parquet over chainage" in note and "1 other track'" in note


def _straight(x0_m: float, x1_m: float, y: np.ndarray | float, name: str) -> TrackMap:
    """A track along east in the demo frame, ``y`` metres north (scalar or per 2 m vertex)."""
    main = demo_track()
    x = np.arange(x0_m, x1_m + 1e-9, 2.0)
    yy = np.broadcast_to(np.asarray(y, float), x.shape) if np.ndim(y) == 0 else np.asarray(y)
    lat, lon, h = (np.asarray(v) for v in main.frame.to_geodetic(
        np.column_stack([x, yy, np.zeros_like(x)])))  # fmt: skip
    return TrackMap.from_latlon(lat, lon, h, name=name, tolerance_m=0.01)


@pytest.mark.parametrize("case", ["past the map's end", "diverging across the limit"])
def test_a_cell_that_reaches_the_map_counts_though_its_position_does_not(case: str) -> None:
    """A reviewer's cases: a loop running past the followed map's end, and one diverging across
    the 25 m limit. A position past the end, or just beyond the limit, stands for a cell that
    reaches the map within it: its places must be bounded too (they lost up to 38.6 and 54 deg
    when only the positions counted)."""
    main = _straight(0.0, 1000.0, 0.0, "main")
    m_main = _masks(main, np.arange(5.0, 996.0, 10.0), 1, 20.0)
    if case == "past the map's end":
        other = _straight(800.0, 1200.0, 4.0, "past end")
    else:
        xo = np.arange(300.0, 700.0 + 1e-9, 2.0)
        other = _straight(300.0, 700.0, 10.0 + 0.1 * (xo - 300.0), "diverging")
    m_other = _masks(other, np.arange(3.0, other.length_m - 2.0, 10.0), 2, 60.0)
    m = merge_worst_case(m_main, [m_other], main).masks
    b = m_other.cell_bounds_m
    s = np.arange(max(b[0], 0.0) + 0.01, min(b[-1], other.length_m) - 0.01, 0.25)
    lat, lon, _ = other.position_at(s)
    p = main.project(lat, lon)
    at, inside = m.position_index(np.asarray(p.chainage_m, float))
    ok = ~np.asarray(p.clamped) & (np.abs(np.asarray(p.offset_m)) <= 25.0) & np.asarray(inside)
    assert ok.sum() > 100
    own = np.asarray(m_other.position_index(s)[0])[ok]
    got = m.effective_mask_deg[np.asarray(at)[ok]]
    assert np.all(got >= m_other.effective_mask_deg[own] - 1e-5)


def test_a_set_merged_with_itself_is_unchanged(scene) -> None:
    """Two passes on one map are looked up by chainage alike: a copy claims nothing the set
    does not (a review: the carried cells' reach and 0.5 m slack raised 7 960 of the quick
    demo's 11 520 bins by up to 53.7 deg, each cell to its neighbours' worst)."""
    main, _, m_main, _ = scene
    res = merge_worst_case(m_main, [m_main], main)
    for attr in ("mask_el_deg", "margin_deg", "source", "support"):
        assert np.array_equal(getattr(res.masks, attr), getattr(m_main, attr)), attr
    assert res.tracks[0].bins_raised == 0 and res.tracks[0].cells_reached == m_main.n_pos


def test_a_second_pass_on_the_same_map_takes_the_cells_it_shares(scene) -> None:
    """A pass on the same map, its positions 3.3 m along and 6.2 m apart over part of the line:
    each cell becomes the worst of its own and exactly the pass's cells sharing chainage with
    it; places every 0.1 m (off the edges) get at least the pass's mask of their chainage."""
    main, _, m_main, _ = scene
    other = _masks(main, np.arange(803.3, 1100.0, 6.2), 7, 60.0)
    m = merge_worst_case(m_main, [other], main).masks
    b, o = m_main.cell_bounds_m, other.cell_bounds_m
    want, want_margin = m_main.mask_el_deg.copy(), m_main.margin_deg.copy()
    for i in range(m_main.n_pos):
        for j in range(other.n_pos):
            if max(b[i], o[j]) < min(b[i + 1], o[j + 1]):
                want[i] = np.maximum(want[i], other.mask_el_deg[j])
                want_margin[i] = np.maximum(want_margin[i], other.margin_deg[j])
    assert np.array_equal(m.mask_el_deg, want) and np.array_equal(m.margin_deg, want_margin)
    s = np.arange(o[0] + 0.05, o[-1], 0.1)
    got = m.effective_mask_deg[np.asarray(m.position_index(s)[0])]
    assert np.all(got >= other.effective_mask_deg[np.asarray(other.position_index(s)[0])] - 1e-5)


def test_what_the_inputs_said_is_kept(scene) -> None:
    """A merge keeps the evidence of every input: the followed set's support where a set
    without support does not reach (0 where it does), the survey checks' warnings of the
    sets merged in, and the record of an earlier merge."""
    from predisat.availability.run import survey_check_notes

    main, _, m_main, m_loop = scene
    prov = {**m_loop.provenance,
            "side_check": {"left": {"agree": 1, "disagree": 12, "swapped": True}}}  # fmt: skip
    v1 = dataclasses.replace(m_loop, support=None, provenance=prov)
    m = merge_worst_case(m_main, [v1], main, labels=["loop v1"]).masks
    assert m.support is not None
    lo, hi = LOOP_M
    far = (m_main.cell_bounds_m[1:] < lo - 10.0) | (m_main.cell_bounds_m[:-1] > hi + 10.0)
    assert np.array_equal(m.support[far], m_main.support[far])
    assert np.all(m.support[m.mask_el_deg > m_main.mask_el_deg] == 0)
    notes = survey_check_notes(m.provenance)
    assert any(n.startswith("merged masks loop v1:") and "left camera" in n for n in notes)
    again = merge_worst_case(m, [m_loop], main, labels=["loop"]).masks
    assert [t["masks"] for t in again.provenance["merged_worst_case"]] == ["loop v1", "loop"]


def test_a_hole_in_another_set_trusts_nothing(scene) -> None:
    """A set given in memory with a hole (a camera dropout, 60 m without positions) is closed
    as read_masks, run_locator and run_availability close it: the cells in the hole trust
    nothing, never the sky of the positions either side."""
    main, _, m_main, _ = scene
    ch = np.arange(603.0, 1400.0, 10.0)
    holed = _masks(main, ch[(ch < 900.0) | (ch > 960.0)], 8, 30.0)
    m = merge_worst_case(m_main, [holed], main).masks
    inside = (m_main.cell_bounds_m[:-1] > 905.0) & (m_main.cell_bounds_m[1:] < 955.0)
    assert inside.sum() >= 3
    assert np.all(m.effective_mask_deg[inside] >= 90.0)
    assert np.all(m.source[inside] == BinSource.ASSUMED)


def test_two_positions_at_one_place_are_refused_by_file_and_row(scene) -> None:
    """Two rows of the loop's masks at one place (an edited file): named, with the fix (they
    gave numpy's "invalid value encountered in divide" and "enu_m contains NaN")."""
    main, _, m_main, m_loop = scene
    k = 10
    rows = np.insert(np.arange(m_loop.n_pos), k + 1, k)
    ch = m_loop.chainage_m[rows].copy()
    ch[k + 1] += 0.01
    dup = MaskSet.from_arrays(
        ch, m_loop.lat_deg[rows], m_loop.lon_deg[rows], m_loop.h_m[rows],
        m_loop.heading_deg[rows], m_loop.mask_el_deg[rows], az_step_deg=m_loop.az_step_deg,
        source=m_loop.source[rows], margin_deg=m_loop.margin_deg[rows],
        support=m_loop.support[rows],
    )  # fmt: skip
    with pytest.raises(ValueError, match=r"loop\.parquet: the positions at chainages .* same"):
        merge_worst_case(m_main, [dup], main, labels=["loop.parquet"])
