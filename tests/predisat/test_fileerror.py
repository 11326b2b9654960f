"""Text-file input shared by the RINEX, SP3 and TLE readers."""

from __future__ import annotations

import gzip
from pathlib import Path

import pytest

from predisat.fileerror import FileLineError, read_text_lines
from predisat.gnss.rinex_nav import RinexError, read_rinex_nav


def test_plain_and_gzip_give_the_same_lines(tmp_path: Path) -> None:
    text = "first line\nsecond  line   \n\nlast"
    plain = tmp_path / "a.txt"
    plain.write_text(text)
    packed = tmp_path / "a.txt.gz"
    packed.write_bytes(gzip.compress(text.encode()))
    assert read_text_lines(plain) == text.splitlines()
    assert read_text_lines(packed) == text.splitlines()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"\x1f\x8b\x08\x00garbage", "corrupt gzip"),
        (b"\x1f\x9d\x90compressed", r"\.Z"),
    ],
)
def test_bad_compression_names_the_file(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "nav.rnx"
    path.write_bytes(content)
    with pytest.raises(RinexError, match=message) as exc:
        read_rinex_nav(path)
    assert str(path) in str(exc.value) and isinstance(exc.value, FileLineError)


def test_missing_file_uses_the_callers_error(tmp_path: Path) -> None:
    with pytest.raises(RinexError, match="no such file"):
        read_text_lines(tmp_path / "absent.rnx", RinexError)
