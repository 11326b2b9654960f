"""``SOURCE_DATE_EPOCH``: pinned, unset, empty or wrong, in this process and in a fresh one."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from predisat.clock import pinned_utc


def test_a_pinned_time_is_read_and_a_wrong_one_named(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    assert pinned_utc() == "2023-11-14T22:13:20+00:00"  # date -u -d @1700000000
    for unset in ("", "  "):
        monkeypatch.setenv("SOURCE_DATE_EPOCH", unset)
        assert pinned_utc() is None
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "2026-01-01")
    with pytest.raises(ValueError, match="SOURCE_DATE_EPOCH='2026-01-01' is not a time"):
        pinned_utc()


def _fresh(code: list[str], value: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "SOURCE_DATE_EPOCH": value}
    return subprocess.run([sys.executable, *code], env=env, capture_output=True, text=True,
                          timeout=120)  # fmt: skip


def test_an_empty_value_is_unset_before_numpy_reads_it() -> None:
    """numpy's f2py (through scipy.special) reads SOURCE_DATE_EPOCH with int() at import: an
    empty one crashed every command, and a worker could not load a task."""
    ours = _fresh(["-c", "import predisat, scipy.special, locator"], "")
    assert ours.returncode == 0, ours.stderr


def test_a_wrong_value_is_one_line_from_the_command_line() -> None:
    out = _fresh(["-m", "predisat", "process", "--help"], "abc")
    assert out.returncode == 1
    assert out.stderr.strip() == (
        "error: SOURCE_DATE_EPOCH='abc' is not a time; give whole seconds since 1970-01-01 UTC "
        "(e.g. 1700000000) or unset it"
    )
    for command in (["-m", "locator", "run", "--help"], ["-m", "locator.cli", "--help"]):
        out = _fresh(command, "abc")
        assert out.returncode == 1 and "Traceback" not in out.stderr, command
        assert out.stderr.startswith("error: SOURCE_DATE_EPOCH='abc' is not a time"), command


def test_the_locator_library_names_the_variable_before_scipy_reads_it() -> None:
    out = _fresh(["-c", "import locator; locator.run_locator"], "abc")
    assert out.returncode != 0 and "ValueError: SOURCE_DATE_EPOCH='abc' is not a time" in out.stderr
