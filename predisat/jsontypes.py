"""JSON documents (provenance records, file metadata, run descriptions): their type and text.

A JSON object's values are of any JSON type, so ``Any`` is the honest value type; naming it
once here (:data:`JsonDict`) keeps ``Any`` out of the public signatures and says why.
:func:`strict_json_text` writes such a document as strict JSON, the one way the project's
files (error models, run descriptions) are written.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any, TypeAlias

import numpy as np

__all__ = ["JsonDict", "strict_json_text"]

JsonDict: TypeAlias = dict[str, Any]
"""A JSON object: string keys, values of any JSON type (nested objects, arrays, numbers...)."""


def _plain(obj: object) -> object:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (tuple, set)):
        return list(obj)
    return str(obj)  # descriptions may hold paths and enums


def _finite_or_null(obj: object) -> object:
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite_or_null(v) for v in obj]
    return obj


def strict_json_text(data: Mapping[str, object]) -> str:
    """``data`` as strict JSON text (indented, ending in a newline).

    numpy scalars and arrays become numbers and lists, tuples and sets lists, other objects
    (paths, enums) their text; NaN and infinities become ``null``, so that jq, browsers and
    JSON schema validators read the file.
    """
    plain = json.loads(json.dumps(data, default=_plain, allow_nan=True))
    return json.dumps(_finite_or_null(plain), indent=2, allow_nan=False) + "\n"
