"""Every file reader, fed damaged copies of valid files, reads them or raises its named error
naming the file (Hypothesis drives :func:`tests.fuzz.harness.mutate`); and the inputs that
found each bug fixed so far, pinned (docs/fuzzing.md)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz.harness import DATA, READERS, mutate, reader, run_one, targets


@pytest.mark.parametrize("name", READERS)
@given(data=st.data())
def test_reader_raises_only_its_named_errors(name: str, data: st.DataObject) -> None:
    r = reader(name)

    def draw(lo: int, hi: int) -> int:
        return data.draw(st.integers(lo, hi))

    seed = r.seeds[draw(0, len(r.seeds) - 1)]
    files = targets(r, seed)
    target = files[draw(0, len(files) - 1)]
    other = r.seeds[draw(0, len(r.seeds) - 1)]
    damaged = mutate(seed[target], draw, other[targets(r, other)[0]])
    with tempfile.TemporaryDirectory() as tmp:
        run_one(r, seed, target, damaged, Path(tmp) / "input")  # FuzzFailure on a bug


@pytest.mark.parametrize("name", READERS)
def test_seeds_are_read(name: str, tmp_path: Path) -> None:
    """The seeds are valid: the fuzzing starts from files the reader accepts."""
    r = reader(name)
    for k, seed in enumerate(r.seeds):
        target = targets(r, seed)[0]
        assert run_one(r, seed, target, seed[target], tmp_path / str(k))


# ---- bugs the fuzzing found (2026-12-04), each pinned by a small input ---------------------


def test_rinex3_record_without_a_satellite_id_is_a_problem_not_an_assertion(
    tmp_path: Path,
) -> None:
    from locator.observations import RinexObsError, read_rinex_obs

    lines = (DATA / "gnss_obs/android_rinex_obs_pixel6_6ep.23o").read_text().splitlines(True)
    k = next(i for i, ln in enumerate(lines) if ln.startswith(">")) + 1
    lines[k] = "?x!" + lines[k][3:]  # the first record of the first epoch
    path = tmp_path / "obs.23o"
    path.write_text("".join(lines))
    obs = read_rinex_obs(path)
    assert any(p.line == k + 1 and "not a satellite id" in p.what for p in obs.problems)
    with pytest.raises(RinexObsError, match=rf"obs.23o, line {k + 1}: .*not a satellite id"):
        read_rinex_obs(path, strict=True)


@pytest.mark.parametrize("suffix", [".csv", ".geojson"])
def test_track_file_not_utf8_names_the_line(suffix: str, tmp_path: Path) -> None:
    from predisat.track import load_track
    from predisat.track.errors import TrackMapError

    path = tmp_path / f"track{suffix}"
    head = b'{"type": "FeatureCollection",\n' if suffix == ".geojson" else b"lat_deg,lon_deg\n"
    path.write_bytes(head + b"50.5,4.6\n50.6,4\xe9.7\n")
    with pytest.raises(TrackMapError, match=r"track\.\w+, line 3: not UTF-8 text.*save"):
        load_track(path)


def test_calibration_not_utf8(tmp_path: Path) -> None:
    from predisat.camera.calibfile import CalibrationError, read_calibration

    path = tmp_path / "cal.yaml"
    path.write_bytes(b"format: predisat-camera\ncamera_name: \xe9\n")
    with pytest.raises(CalibrationError, match=r"cal\.yaml: not UTF-8 text.*UTF-8 YAML"):
        read_calibration(path)


def test_survey_yaml_not_utf8(tmp_path: Path) -> None:
    from predisat.survey import Survey, SurveyError

    (tmp_path / "survey.yaml").write_bytes(b"format: predisat-survey\ndescription: \xe9\n")
    with pytest.raises(SurveyError, match=r"survey\.yaml is not UTF-8 text"):
        Survey.load(tmp_path)


def test_mask_file_metadata_not_utf8(tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    from predisat.masks.fileformat import METADATA_KEY, MaskFileError, read_masks

    r = reader("masks")
    good = tmp_path / "good.parquet"
    good.write_bytes(r.seeds[0]["input.parquet"])
    table = pq.read_table(good)
    meta = dict(table.schema.metadata or {})
    meta[METADATA_KEY] = b'{"format": "\xe9'
    pq.write_table(table.replace_schema_metadata(meta), tmp_path / "bad.parquet")
    with pytest.raises(MaskFileError, match=r"bad\.parquet: the .* metadata is not JSON"):
        read_masks(tmp_path / "bad.parquet")


def test_calibration_image_size_infinite(tmp_path: Path) -> None:
    from predisat.camera.calibfile import CalibrationError, read_calibration

    seed = next(iter(reader("calibration").seeds[0].values()))
    path = tmp_path / "cal.yaml"
    path.write_bytes(seed.replace(b"image_width: 32", b"image_width: .inf"))
    assert b".inf" in path.read_bytes()
    with pytest.raises(CalibrationError, match=r"cal\.yaml: field 'image_width' must be a number"):
        read_calibration(path)


def test_mask_file_column_name_not_utf8() -> None:
    from predisat.masks.fileformat import MaskFileError, read_masks

    path = DATA / "fuzz/masks_column_name_not_utf8.parquet"
    with pytest.raises(MaskFileError, match=r"not_utf8\.parquet: a column name is not UTF-8"):
        read_masks(path)
