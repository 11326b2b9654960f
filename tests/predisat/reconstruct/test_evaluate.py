"""Tests of predisat.reconstruct.evaluate: counts against an explicit elevation grid, calibration,
and an
evaluation of masks processed from a tiny synthetic survey."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from predisat.camera.models import CameraModel
from predisat.cli.evaluate import add_arguments as add_evaluate_arguments
from predisat.cli.evaluate import run as evaluate_from_args
from predisat.masks.margins import MarginTable, sector_of
from predisat.reconstruct.evaluate import (
    Comparison,
    calibrate_margin,
    compare,
    count_above,
    evaluate_masks,
    format_table,
    load_truth,
    position_false_trust,
    trust_counts,
)

GRID = (np.arange(900) + 0.5) * 0.1  # the 0.1 deg elevation grid, explicitly


def test_count_above_matches_an_explicit_grid() -> None:
    rng = np.random.default_rng(0)
    t = np.concatenate([rng.uniform(-5, 95, 500), GRID[:50], [0.0, 90.0, 0.05, 89.95]])
    want = (GRID[None, :] > t[:, None]).sum(axis=1)
    np.testing.assert_array_equal(count_above(t), want)


def test_trust_counts_match_an_explicit_grid() -> None:
    rng = np.random.default_rng(1)
    m, t, mg = rng.uniform(0, 90, 300), rng.uniform(0, 90, 300), rng.uniform(0, 5, 300)
    trusted, good, los = trust_counts(m, t, mg)
    g = GRID[None, :]
    np.testing.assert_array_equal(trusted, (g > (m + mg)[:, None]).sum(1))
    np.testing.assert_array_equal(good, ((g > (m + mg)[:, None]) & (g > t[:, None])).sum(1))
    np.testing.assert_array_equal(los, (g > t[:, None]).sum(1))


def test_sector_of() -> None:
    az = np.array([0.0, 45.0, 46.0, 90.0, 134.0, 136.0, 180.0, 270.0, 314.0, 316.0])
    got = sector_of(az, 0.0)
    assert list(got) == ["along", "cross", "cross", "cross", "cross", "along", "along",
                         "cross", "cross", "along"]  # fmt: skip
    # heading 90: the cross-track directions are north and south
    assert list(sector_of([0.0, 90.0, 180.0, 270.0], 90.0)) == ["cross", "along", "cross", "along"]


def _synthetic_comparison(seed: int = 2) -> Comparison:
    rng = np.random.default_rng(seed)
    n_pos, n_az = 40, 72
    truth = rng.uniform(0, 40, (n_pos, n_az))
    err = rng.normal(0.0, 1.0, (n_pos, n_az))
    err[:, :36] *= 3.0  # the first half of the bins (cross-track below) is worse
    mask = np.clip(truth + err, 0, 90)
    az = np.arange(n_az) * 5.0
    sector = np.where(np.abs(np.mod(az - 0.0, 180.0) - 90.0) <= 45.0, "cross", "along")
    return Comparison(
        chainage_m=np.arange(n_pos) * 10.0, mask_el_deg=mask, truth_el_deg=truth,
        source=np.zeros((n_pos, n_az), np.uint8), sector=np.broadcast_to(sector, mask.shape),
        az_deg=az,
    )  # fmt: skip


def _los_share(mask: np.ndarray, truth: np.ndarray, margin: float) -> float:
    g = GRID[None, None, :]
    trusted = g > (mask + margin)[..., None]
    return float((trusted & (g > truth[..., None])).sum() / trusted.sum())


def test_calibrated_margin_is_the_smallest_reaching_the_target() -> None:
    comp = _synthetic_comparison()
    table = calibrate_margin(comp, target=0.999)
    assert set(table.table["sector"]) == {"cross", "along"}
    for sec in ("cross", "along"):
        row = table.table[(table.table.sector == sec) & (table.table.source == "observed")]
        margin = float(row.margin_deg.iloc[0])
        sel = comp.sector[0] == sec
        m, t = comp.mask_el_deg[:, sel], comp.truth_el_deg[:, sel]
        assert margin > 0
        assert _los_share(m, t, margin) >= 0.999
        assert _los_share(m, t, margin - 0.1) < 0.999
        assert float(row.los_share.iloc[0]) == pytest.approx(_los_share(m, t, margin))
    cross = table.table[(table.table.sector == "cross") & (table.table.source == "observed")]
    along = table.table[(table.table.sector == "along") & (table.table.source == "observed")]
    # cross-track bins are 0..45 and 135..180 of a 5 deg ring: a mix, but noisier on average
    assert float(cross.margin_deg.iloc[0]) != float(along.margin_deg.iloc[0])


def test_evaluate_with_margin_meets_target_on_the_calibration_set(tmp_path: Path) -> None:
    comp = _synthetic_comparison()
    table = calibrate_margin(comp, target=0.999, by=())
    assert table.table.margin_deg.nunique() == 1
    res = evaluate_masks(comp, table)
    row = res[(res.sector == "all") & (res.source == "all")].iloc[0]
    margin = float(table.table.margin_deg.iloc[0])
    assert row.false_trust_margin == pytest.approx(
        1.0 - _los_share(comp.mask_el_deg, comp.truth_el_deg, margin)
    )
    assert row.false_trust_margin <= 0.001 < row.false_trust
    g = GRID[None, None, :]
    vis = g > comp.truth_el_deg[..., None]
    lost = vis & ~(g > (comp.mask_el_deg + margin)[..., None])
    assert row.sky_lost_margin == pytest.approx(lost.sum() / vis.sum())
    err = comp.mask_el_deg - comp.truth_el_deg
    assert row.unsafe_share == pytest.approx(np.mean(err < -0.1))
    assert row.median_error_deg == pytest.approx(np.median(err))
    table.to_json(tmp_path / "m.json")
    back = MarginTable.from_json(tmp_path / "m.json")
    np.testing.assert_array_equal(back.table.margin_deg, table.table.margin_deg)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    from predisat.reconstruct.batch import process_survey
    from predisat.reconstruct.params import PipelineParams
    from predisat.synth.generate import generate_survey
    from predisat.track.map import demo_track

    out = tmp_path_factory.mktemp("synth")
    generate_survey(
        demo_track(), 4000.0, 4040.0, sky="clear", seed=5, out_dir=out,
        camera=CameraModel.pinhole_from_fov(160, 120, 74.0), progress=False,
    )  # fmt: skip
    masks_dir = out / "processed"
    process_survey(out / "survey", masks_dir, PipelineParams(chunk_m=500.0), progress=False)
    return out, masks_dir


def test_evaluate_tiny_survey(tiny: tuple[Path, Path]) -> None:
    from predisat.masks.fileformat import read_masks

    synth, masks_dir = tiny
    masks = read_masks(masks_dir / "masks.parquet")
    truth = load_truth(synth)
    comp = compare(masks, truth)
    assert comp.chainage_m.size == 5 and comp.unmatched == 0
    res = evaluate_masks(comp)
    num = res[res.n_bins > 0].drop(columns=["sector", "source"]).to_numpy(float)
    assert np.isfinite(num).all()
    # unsafe share computed independently: nearest truth row by chainage, same 0.5 deg bins
    rows = [int(np.argmin(np.abs(truth.chainage_m - s))) for s in masks.chainage_m]
    assert truth.az_deg.size == masks.n_az
    diff = masks.mask_el_deg.astype(float) - truth.mask_el_deg[rows]
    all_row = res[(res.sector == "all") & (res.source == "all")].iloc[0]
    assert all_row.unsafe_share == pytest.approx(np.mean(diff < -0.1))
    assert all_row.n_bins == diff.size


def test_evaluate_cli(tiny: tuple[Path, Path], tmp_path: Path, capsys) -> None:
    synth, masks_dir = tiny
    parser = argparse.ArgumentParser()
    add_evaluate_arguments(parser)
    args = parser.parse_args(
        [str(masks_dir), "--truth", str(synth / "truth"), "--calibrate", "--out", str(tmp_path)]
    )
    table = evaluate_from_args(args)
    assert "false_trust_margin" in table.columns
    doc = json.loads((tmp_path / "evaluation.json").read_text())
    assert doc["n_positions"] == 5
    assert (tmp_path / "margins.json").is_file() and (tmp_path / "evaluation.csv").is_file()
    assert (tmp_path / "evaluation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    args2 = parser.parse_args(
        [str(masks_dir / "masks.parquet"), "--truth", str(synth),
         "--margins", str(tmp_path / "margins.json")]
    )  # fmt: skip
    again = evaluate_from_args(args2)
    np.testing.assert_allclose(
        again.false_trust_margin.to_numpy(float), table.false_trust_margin.to_numpy(float),
        equal_nan=True,
    )  # fmt: skip
    out = capsys.readouterr().out
    assert "observed" in out and "false trust per position: worst " in out

    def refuse(name: str) -> None:
        raise ValueError(f"non-standard JSON constant {name}")

    doc = json.loads((tmp_path / "evaluation.json").read_text(), parse_constant=refuse)
    assert 0 <= doc["positions_above_limit"] <= 5 and "worst_position" in doc


def test_position_false_trust_counts_each_positions_grid_directions() -> None:
    """Against the explicit 0.1 deg grid: a direction is trusted above the mask and falsely so
    at or below the truth."""
    comp = _synthetic_comparison()
    per = position_false_trust(comp)
    for i in range(comp.chainage_m.size):
        trusted = GRID[None, :] > comp.mask_el_deg[i][:, None]
        blocked = GRID[None, :] <= comp.truth_el_deg[i][:, None]
        want = (trusted & blocked).sum() / trusted.sum()
        assert per[i] == pytest.approx(want)
    assert (per > 0).any()  # the noisy masks trust some blocked sky somewhere


def test_confident_margin_holds_on_other_surveys_more_often() -> None:
    # held-out surveys from the same generator: the in-sample point estimate meets the target
    # on about half of them; the block-bootstrap margin on most
    def coverage(confidence: float | None) -> float:
        hits = []
        for s in range(12):
            table = calibrate_margin(
                _synthetic_comparison(100 + s), target=0.999, by=(), confidence=confidence
            )
            margin = float(table.table.margin_deg.iloc[0])
            for k in range(8):
                other = _synthetic_comparison(1000 + 10 * s + k)
                hits.append(_los_share(other.mask_el_deg, other.truth_el_deg, margin) >= 0.999)
        return float(np.mean(hits))

    point, confident = coverage(None), coverage(0.95)
    assert point < 0.7
    assert confident >= 0.75 and confident > point + 0.2


def test_confident_margin_is_never_below_the_point_estimate() -> None:
    comp = _synthetic_comparison()
    point = calibrate_margin(comp, target=0.999)
    conf = calibrate_margin(comp, target=0.999, confidence=0.9, block_m=50.0)
    merged = point.table.merge(conf.table, on=["sector", "source"], suffixes=("_p", "_c"))
    assert (merged.margin_deg_c >= merged.margin_deg_p).all()
    assert (merged.margin_deg_c > merged.margin_deg_p).any()
    assert conf.meta["confidence"] == 0.9 and conf.meta["block_m"] == 50.0
    with pytest.raises(ValueError, match="confidence"):
        calibrate_margin(comp, confidence=1.5)
    with pytest.raises(ValueError, match="block_m"):
        calibrate_margin(comp, confidence=0.9, block_m=0.0)


def test_block_weights_are_whole_blocks_of_the_line() -> None:
    from predisat.reconstruct.evaluate import _block_weights

    s = np.arange(45) * 10.0
    w = _block_weights(s, 100.0, 50, seed=3)
    assert w.shape == (50, 45)
    assert (w.sum(axis=1) == 45).all()  # every resample as long as the line
    # a resample is a union of 10-position runs: its support has few starts (wrapped runs)
    for row in w:
        on = row > 0
        starts = np.flatnonzero(on & ~np.roll(on, 1))
        assert 1 <= starts.size <= 5


def test_a_group_from_few_positions_takes_its_sectors_margin() -> None:
    comp = _synthetic_comparison()
    source = comp.source.copy()
    source[:3, :36] = 1  # a few RECONSTRUCTED bins, at 3 positions only
    small = Comparison(comp.chainage_m, comp.mask_el_deg, comp.truth_el_deg, source,
                       comp.sector, comp.az_deg)  # fmt: skip
    table = calibrate_margin(small, target=0.999, min_positions=10).table
    rec = table[(table.source == "reconstructed") & (table.n_bins > 0)]
    assert len(rec) > 0 and not rec.sampled.any()
    for _, row in rec.iterrows():
        peers = table[(table.sector == row.sector) & table.sampled]
        assert row.margin_deg >= peers.margin_deg.max()
    # with the threshold lowered the same group is calibrated on its own
    alone = calibrate_margin(small, target=0.999, min_positions=1).table
    assert alone[(alone.source == "reconstructed") & (alone.n_bins > 0)].sampled.all()


def test_process_writes_margins_and_evaluate_uses_them(
    tiny: tuple[Path, Path], tmp_path: Path
) -> None:
    import dataclasses
    import hashlib
    import shutil

    from predisat.masks.fileformat import read_masks, write_masks
    from predisat.reconstruct.batch import process_survey
    from predisat.reconstruct.params import PipelineParams

    synth, masks_dir = tiny
    lut = {("cross", "observed"): 1.0, ("cross", "reconstructed"): 2.0,
           ("cross", "assumed"): 3.0, ("along", "observed"): 4.0,
           ("along", "reconstructed"): 5.0, ("along", "assumed"): 6.0}  # fmt: skip
    rows = [{"sector": k[0], "source": k[1], "margin_deg": v} for k, v in lut.items()]
    MarginTable(pd.DataFrame(rows), 0.999).to_json(tmp_path / "margins.json")
    with pytest.raises(FileNotFoundError, match=r"nope\.json"):
        process_survey(synth / "survey", tmp_path / "x", margins=tmp_path / "nope.json")
    assert not (tmp_path / "x" / "chunks").exists()  # refused before any work

    out = tmp_path / "resumed"
    shutil.copytree(masks_dir, out)
    res = process_survey(synth / "survey", out, PipelineParams(chunk_m=500.0), progress=False,
                         margins=tmp_path / "margins.json")  # fmt: skip
    assert res.chunks_done == 0 and res.chunks_skipped >= 1  # margins redo no chunk
    bare, got = read_masks(masks_dir / "masks.parquet"), read_masks(out / "masks.parquet")
    np.testing.assert_array_equal(got.mask_el_deg, bare.mask_el_deg)
    # the expected margin per bin, from the sector rule written out here
    rel = np.mod(got.az_deg[None, :] - got.heading_deg[:, None], 180.0)
    cross = np.abs(rel - 90.0) <= 45.0
    names = np.array(["observed", "reconstructed", "assumed"])[got.source]
    want = np.vectorize(lambda c, n: lut[("cross" if c else "along", n)])(cross, names)
    np.testing.assert_array_equal(np.broadcast_to(got.margin_deg, want.shape), want)
    sha = hashlib.sha256((tmp_path / "margins.json").read_bytes()).hexdigest()
    assert got.provenance["margins"]["sha256"] == sha

    # evaluate reads a file's margins: false trust counted on the explicit elevation grid.
    # This tiny survey's masks are closed (90 deg), so the masks are the truth plus noise here.
    truth = load_truth(synth)
    rows_t = [int(np.argmin(np.abs(truth.chainage_m - s))) for s in got.chainage_m]
    noisy = truth.mask_el_deg[rows_t] + np.random.default_rng(1).normal(0.0, 3.0, want.shape)
    masks = dataclasses.replace(got, mask_el_deg=np.clip(noisy, 0.0, 90.0).astype(np.float32))
    path = write_masks(masks, tmp_path / "noisy.parquet")
    res_table = evaluate_masks(compare(read_masks(path), truth))
    g = GRID[None, None, :]
    trusted = g > (masks.mask_el_deg.astype(float) + want)[..., None]
    vis = g > truth.mask_el_deg[rows_t][..., None]
    assert 0 < (trusted & ~vis).sum() < trusted.sum()
    all_row = res_table[(res_table.sector == "all") & (res_table.source == "all")].iloc[0]
    assert all_row.false_trust_margin == pytest.approx(1.0 - (trusted & vis).sum() / trusted.sum())
    assert all_row.sky_lost_margin == pytest.approx(1.0 - (trusted & vis).sum() / vis.sum())
    assert all_row.sky_lost_margin > all_row.sky_lost  # the margins cost sky


def test_process_checks_margin_tables_before_any_work(
    tiny: tuple[Path, Path], tmp_path: Path
) -> None:
    import shutil

    from predisat.reconstruct.batch import process_survey
    from predisat.reconstruct.params import PipelineParams

    synth, masks_dir = tiny
    # a real calibration: groups without bins get 90 deg and NaN shares (null in JSON)
    real = calibrate_margin(_synthetic_comparison())
    assert real.table.los_share.isna().any()
    real.to_json(tmp_path / "real.json")
    out = tmp_path / "resumed"
    shutil.copytree(masks_dir, out)
    res = process_survey(synth / "survey", out, PipelineParams(chunk_m=500.0), progress=False,
                         margins=tmp_path / "real.json")  # fmt: skip
    rec = res.masks.provenance["margins"]["table"]
    assert len(rec) == 6 and any(r["los_share"] is None for r in rec)

    good = [{"sector": s, "source": c, "margin_deg": 1.0}
            for s in ("cross", "along") for c in ("observed", "reconstructed", "assumed")]
    cases = {
        "no margin for": good[:-1],  # one group missing: it would take the largest silently
        "unknown": [*good, {"sector": "Cross", "source": "observed", "margin_deg": 0.0}],
        "finite and >= 0": [*good[:-1], {**good[-1], "margin_deg": -1.0}],
        "no column": [{k: v for k, v in r.items() if k != "source"} for r in good],
    }
    for i, (message, rows) in enumerate(cases.items()):
        MarginTable(pd.DataFrame(rows), 0.999).to_json(tmp_path / f"bad{i}.json")
        with pytest.raises(ValueError, match=message):
            process_survey(synth / "survey", tmp_path / f"x{i}", margins=tmp_path / f"bad{i}.json")
        assert not (tmp_path / f"x{i}" / "chunks").exists()
    (tmp_path / "junk.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match=r"not a margin table|no 'target'"):
        process_survey(synth / "survey", tmp_path / "y", margins=tmp_path / "junk.json")


def test_margin_table_refuses_bins_of_a_missing_group() -> None:

    rows = [{"sector": "cross", "source": "observed", "margin_deg": 0.0},
            {"sector": "along", "source": "observed", "margin_deg": 3.0}]  # fmt: skip
    table = MarginTable(pd.DataFrame(rows), 0.999)
    sector = np.array([["cross", "along"]])
    np.testing.assert_array_equal(table.margin_for(sector, np.zeros((1, 2), np.uint8)), [[0, 3]])
    with pytest.raises(ValueError, match="'cross', 'assumed'"):
        table.margin_for(sector, np.array([[2, 0]], np.uint8))


def test_format_table_keeps_rare_shares_visible() -> None:
    table = pd.DataFrame({
        "sector": ["all"], "p95_error_deg": [34.99987], "unsafe_share": [6.5e-4],
        "false_trust": [5.37e-6], "false_trust_margin": [0.0], "sky_lost": [0.153912],
    })  # fmt: skip
    header, row = format_table(table).splitlines()
    cells = dict(zip(header.split(), row.split(), strict=True))
    # shares in percent (as the figures and the README), named so
    assert cells["false_trust_%"] == "5.37e-04" and cells["unsafe_share_%"] == "6.50e-02"
    assert float(cells["false_trust_margin_%"]) == 0.0
    assert cells["p95_error_deg"] == "34.9999" and cells["sky_lost_%"] == "15.39"
    assert "sky_lost" not in header.split()  # no bare fraction column left


def test_no_visible_sky_has_no_sky_lost_share() -> None:
    """In a tunnel nothing is truly visible: the share of sky lost is of nothing (n/a), not
    0 % (a user trial read "sky_lost_% 0.0" there as a perfect mask)."""
    base = _synthetic_comparison()
    shut = Comparison(
        chainage_m=base.chainage_m, mask_el_deg=np.full_like(base.mask_el_deg, 90.0),
        truth_el_deg=np.full_like(base.truth_el_deg, 90.0), source=base.source,
        sector=base.sector, az_deg=base.az_deg,
    )  # fmt: skip
    table = evaluate_masks(shut)
    held = table[table["n_bins"] > 0]  # (groups without bins are NaN throughout, as before)
    assert len(held) and held["sky_lost"].isna().all() and (held["false_trust"] == 0.0).all()
    text = format_table(table)
    assert "n/a" in text and "nan" not in text.lower().replace("n/a", "")
    # with visible sky the share is a number, as before
    seen = evaluate_masks(base)
    assert np.isfinite(seen.loc[seen["n_bins"] > 0, "sky_lost"]).all()


def test_evaluate_warns_of_the_truth_of_another_survey(tiny: tuple[Path, Path], tmp_path) -> None:
    """A user trial scored one world's masks against another's truth and read 7.4 % false
    trust without a word: positions pair by chainage alone."""
    import shutil

    from predisat.cli.evaluate import other_survey_note
    from predisat.masks.fileformat import read_masks

    synth, masks_dir = tiny
    prov = read_masks(masks_dir / "masks.parquet").provenance
    for given in (synth, synth / "truth", synth / "truth" / "true_masks.npz"):
        assert other_survey_note(prov, given) is None  # its own truth, however given
    other = tmp_path / "other"
    shutil.copytree(synth / "survey", other / "survey")
    shutil.copytree(synth / "truth", other / "truth")
    yaml_path = other / "survey" / "survey.yaml"
    yaml_path.write_text(yaml_path.read_text().replace("seed 5", "seed 6"))
    note = other_survey_note(prov, other / "truth")
    assert note is not None and "not of the survey the masks were made from" in note
    assert other_survey_note({}, other) is None  # masks that do not say: nothing to tell


def test_terrain_bins_do_not_dilute_the_assumed_bins_margin() -> None:
    """Masks raised to the terrain: the TERRAIN bins take the ASSUMED group's margin, but their
    line of sight must not hide the assumed bins' false trust (a user trial's canyon: a rock
    wall 250-300 m behind the train over the assumed 5 deg, 0.118 % of the assumed bins
    trusted falsely, 0.045 % pooled with the terrain bins, calibrated margin 0)."""
    from predisat.masks.maskset import BinSource

    rng = np.random.default_rng(4)
    n_pos, n_az = 40, 72
    truth = rng.uniform(0, 20, (n_pos, n_az))
    mask = truth + 0.5
    source = np.full((n_pos, n_az), BinSource.TERRAIN, np.uint8)
    source[:, :4] = BinSource.ASSUMED
    mask[:, :4] = 5.0
    truth[:, :4] = rng.uniform(3.0, 7.0, (n_pos, 4))  # a wall over the assumed default
    sector = np.full((n_pos, n_az), "along")
    comp = Comparison(chainage_m=np.arange(n_pos) * 10.0, mask_el_deg=mask,
                      truth_el_deg=truth, source=source, sector=sector,
                      az_deg=np.arange(n_az) * 5.0)  # fmt: skip
    own = source == BinSource.ASSUMED
    assert _los_share(mask[own], truth[own], 0.0) < 0.999  # the assumed bins fail alone
    assert _los_share(mask, truth, 0.0) >= 0.999  # pooled with the terrain bins they pass
    table = calibrate_margin(comp, target=0.999)
    row = table.table[(table.table.sector == "along") & (table.table.source == "assumed")]
    margin = float(row.margin_deg.iloc[0])
    assert margin > 0 and _los_share(mask[own], truth[own], margin) >= 0.999
