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
