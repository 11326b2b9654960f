"""Average the weights of sky networks trained from one start (a "model soup"), for a candidate.

Usage (needs ``onnx``: ``.venv/bin/pip install onnx``)::

    python scripts/sky_soup.py --out /tmp/soup/sky_unet.onnx \
        predisat/data/models/sky_unet.onnx /tmp/e10s1/sky_unet.onnx

The networks must be the same graph (``scripts/train_sky_cnn.py`` with the same channels and
input size; batch normalisation is folded into the convolutions on export, so the average is
over the folded weights). Averaging only makes sense for networks fine-tuned from one common
file (``--init``), as ``e10`` with two seeds (docs/segmentation.md, "Larger candidates"). The
card written beside the output is the first network's, with ``recipe = "soup"`` and the
SHA-256 of every member. Score it with ``scripts/eval_sky.py --method ensemble --net OUT``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "members",
        nargs="+",
        type=Path,
        metavar="ONNX",
        help="networks to average (each with its .json card beside it)",
    )
    parser.add_argument("--out", type=Path, required=True, metavar="ONNX")
    args = parser.parse_args(argv)
    if len(args.members) < 2:
        parser.error("give at least two networks to average")
    for m in args.members:
        if not (m.is_file() and m.with_suffix(".json").is_file()):
            parser.error(f"{m} or its card {m.with_suffix('.json').name} is missing")
    try:
        import onnx
        from onnx import numpy_helper
    except ImportError:
        parser.error("reading ONNX weights needs onnx: .venv/bin/pip install onnx")
    models = [onnx.load(str(m)) for m in args.members]
    names = [[t.name for t in m.graph.initializer] for m in models]
    for m, n in zip(args.members[1:], names[1:], strict=True):
        if n != names[0]:
            parser.error(f"{m} is not the same graph as {args.members[0]} (other weight names)")
    soup = models[0]
    for k, tensor in enumerate(soup.graph.initializer):
        arrays = [numpy_helper.to_array(m.graph.initializer[k]) for m in models]
        if any(a.shape != arrays[0].shape for a in arrays):
            parser.error(f"weight {tensor.name} has other shapes in the members")
        if arrays[0].dtype.kind != "f":  # shapes and indices: identical in one graph
            continue
        mean = np.mean(np.stack(arrays).astype(np.float64), axis=0).astype(arrays[0].dtype)
        tensor.CopyFrom(numpy_helper.from_array(mean, tensor.name))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(soup, str(args.out))
    card = json.loads(args.members[0].with_suffix(".json").read_text(encoding="utf-8"))
    card["recipe"] = "soup"
    card["soup_of"] = [
        {
            "path": str(m),
            "recipe": json.loads(m.with_suffix(".json").read_text())["recipe"],
            "sha256": hashlib.sha256(m.read_bytes()).hexdigest(),
        }
        for m in args.members
    ]
    card.pop("validation", None)  # the members' scores, not the soup's
    args.out.with_suffix(".json").write_text(json.dumps(card, indent=1), encoding="utf-8")
    print(f"wrote {args.out} (mean of {len(models)} networks) and its card")
    return 0


if __name__ == "__main__":
    sys.exit(main())
