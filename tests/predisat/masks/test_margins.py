"""Margin tables (predisat.masks.margins): files that are not one are refused with the fix."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from predisat.masks.margins import MarginTable


@pytest.mark.parametrize(
    ("text", "what"),
    [
        # the trial's mistake: evaluate's evaluation.json given as --margins
        (json.dumps({"rows": [], "meta": {}}), "no 'target'"),
        (json.dumps({"target": 0.999}), "no 'margins'"),
        (json.dumps([1, 2]), "not a JSON object"),
        ("sector,source\n", "not JSON"),
    ],
)
def test_not_a_margin_table_names_the_file_and_the_command_that_makes_one(
    tmp_path: Path, text: str, what: str
) -> None:
    path = tmp_path / "evaluation.json"
    path.write_text(text)
    with pytest.raises(ValueError) as exc:
        MarginTable.from_json(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: not a margin table ({what}")
    # before: "write it with MarginTable.to_json", a library call, not the command
    assert "predisat evaluate" in msg and "--calibrate" in msg and "margins.json" in msg


def _rows(margin_deg: float = 1.0) -> list[dict]:
    from predisat.masks.margins import MARGIN_SOURCES, SECTORS

    return [{"sector": s, "source": c, "margin_deg": margin_deg}
            for s in SECTORS for c in MARGIN_SOURCES]  # fmt: skip


def test_two_rows_for_one_group_are_refused_not_the_last_one_taken(tmp_path: Path) -> None:
    """A user trial appended a copy of one row with 0 deg: the later row silently won and
    half of the bins lost their margin."""
    import pandas as pd

    rows = _rows()
    MarginTable(pd.DataFrame(rows), 0.999).check("ok.json")  # the table without the copy
    dup = [*rows, {**rows[0], "margin_deg": 0.0}]
    match = r"dup.json: rows 0 and \d+ both give .* \(margins 1 and 0"
    with pytest.raises(ValueError, match=match):
        MarginTable(pd.DataFrame(dup), 0.999).check("dup.json")


@pytest.mark.parametrize(
    ("doc", "what"),
    [
        ({"target": 0.999, "margins": {"cross": 1.0}}, "'margins' must be a list of rows"),
        ({"target": "high", "margins": _rows()}, "'target' and 'el_step_deg' must be numbers"),
    ],
)
def test_a_malformed_table_names_the_file_not_a_pandas_error(
    tmp_path: Path, doc: dict, what: str
) -> None:
    path = tmp_path / "margins.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError) as exc:
        MarginTable.from_json(path)
    assert str(exc.value).startswith(f"{path}: {what}") and "--calibrate" in str(exc.value)
