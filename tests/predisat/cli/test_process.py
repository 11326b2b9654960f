"""``predisat process``: its options reach :func:`predisat.reconstruct.batch.process_survey`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from predisat.cli import app as cli


def _survey(tmp_path: Path) -> Path:
    survey = tmp_path / "survey"
    survey.mkdir()
    (survey / "survey.yaml").write_text("format: predisat-survey/1\n")
    return survey


def _two_tracks(path: Path) -> Path:
    """A GeoJSON of two parallel named tracks, ``A`` (1 km) and ``B`` (2 km), and a siding."""

    def line(name: str, lat_deg: float, km: float, usage: str) -> dict[str, object]:
        lons = [4.0 + i * km / 10.0 / 71.0 for i in range(11)]  # ~71 km per degree at 50 N
        return {"type": "Feature", "properties": {"name": name, "usage": usage},
                "geometry": {"type": "LineString",
                             "coordinates": [[lon, lat_deg] for lon in lons]}}  # fmt: skip

    features = [line("A", 50.0, 1.0, "main"), line("B", 50.001, 2.0, "main"),
                line("C", 50.002, 0.5, "siding")]  # fmt: skip
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    return path


def test_process_selects_a_track_in_a_file_of_several(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from predisat.cli import process as cli_process

    survey = _survey(tmp_path)
    tracks = _two_tracks(tmp_path / "tracks.geojson")
    seen: dict[str, object] = {}

    def fake(survey_dir, out, params, **kw):  # type: ignore[no-untyped-def]
        seen["track"] = kw["track"]
        raise SystemExit(0)

    monkeypatch.setattr(cli_process, "process_survey", fake)
    base = ["process", str(survey), "--out", str(tmp_path / "o"), "--track", str(tracks)]

    assert cli.main(base) == 2  # several tracks: the fix names the option that exists
    assert "--track-name" in capsys.readouterr().err
    for extra, length_km in ((["--track-name", "B"], 2.0),
                             (["--where", "usage=main", "--chain", "longest"], 2.0),
                             (["--where", "usage=siding"], 0.5)):  # fmt: skip
        with pytest.raises(SystemExit):
            cli.main([*base, *extra])
        track = seen.pop("track")
        assert track.length_m / 1000.0 == pytest.approx(length_km, rel=0.05)  # type: ignore[attr-defined]


def test_process_track_selection_needs_a_track_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    survey = _survey(tmp_path)
    for extra in (["--track-name", "A"], ["--where", "usage=main"]):
        with pytest.raises(SystemExit) as exc:
            cli.main(["process", str(survey), "--out", str(tmp_path / "o"), *extra])
        assert exc.value.code == 2
        assert f"{extra[0]} is for a --track file" in capsys.readouterr().err


@pytest.mark.parametrize("option", ["--dem", "--margins", "--track"])
def test_process_missing_input_file_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str
) -> None:
    survey = _survey(tmp_path)
    missing = str(tmp_path / "nope.x")
    with pytest.raises(SystemExit) as exc:
        cli.main(["process", str(survey), "--out", str(tmp_path / "o"), option, missing])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    # before: argparse's whole usage text first
    assert err.splitlines() == [
        f"predisat process: error: argument {option}: {missing}: no such file; give "
        + err.split("; give ", 1)[1].rstrip("\n")
    ]


def test_process_other_parse_errors_keep_the_usage(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit):
        cli.main(["process", str(_survey(tmp_path)), "--out", str(tmp_path / "o"),
                  "--chunk-m", "-1"])  # fmt: skip
    assert capsys.readouterr().err.startswith("usage:")


def test_process_quiet_help_says_what_it_silences(capsys: pytest.CaptureFixture[str]) -> None:
    # --quiet drops the "mask bins: ..." summary too (predisat.reconstruct.batch); the help
    # said only "no progress bar"
    with pytest.raises(SystemExit):
        cli.main(["process", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "'mask bins: ...'" in out and "warnings are still printed" in out


def test_a_run_whose_every_frame_was_refused_ends_with_status_2(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """All frames refused at segmentation (EXIF-tagged, 12-bit data, ...) gave masks all
    assumed and exit 0: safe, but a user trial took it for a finished survey."""
    from types import SimpleNamespace

    from predisat.cli import process as cli_process
    from predisat.reconstruct.badframes import BadFrame

    def result(n_bad: int) -> SimpleNamespace:
        bad = tuple(BadFrame(f"f{k}", f"image f{k}.jpg carries EXIF Orientation 2", "segment")
                    for k in range(n_bad))  # fmt: skip
        return SimpleNamespace(n_frames=3, bad_frames=bad)

    for n_bad, status in ((2, 0), (3, 2)):
        monkeypatch.setattr(cli_process, "run", lambda args, n=n_bad: result(n))
        assert cli.cmd_process(SimpleNamespace()) == status
        err = capsys.readouterr().err
        assert ("every one of the 3 frames was refused" in err) == (status == 2)
        assert ("f0.jpg carries EXIF Orientation 2" in err) == (status == 2)


def test_a_path_the_system_cannot_look_up_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An --out name over 255 bytes made pathlib's stat raise inside argparse: a traceback."""
    long_name = str(tmp_path / ("très_long_nom_" * 20))
    with pytest.raises(SystemExit) as info:
        cli.main(["process", str(_survey(tmp_path)), "--out", long_name])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "File name too long; give a shorter or valid path" in err and "Traceback" not in err
