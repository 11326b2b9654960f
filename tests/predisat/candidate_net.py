"""A candidate sky network for tests: the shipped one copied, its card changed if asked."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

__all__ = ["net_copy"]


def net_copy(folder: Path, input_px: int | None = None) -> Path:
    """The shipped sky network copied to ``folder`` (its card's input size changed if given)."""
    folder.mkdir(parents=True)
    src = resources.files("predisat") / "data" / "models"
    (folder / "net.onnx").write_bytes((src / "sky_unet.onnx").read_bytes())
    card = json.loads((src / "sky_unet.json").read_text())
    if input_px is not None:
        card["input_px"] = input_px
    (folder / "net.json").write_text(json.dumps(card))
    return folder / "net.onnx"
