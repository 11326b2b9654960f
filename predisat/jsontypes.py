"""Type aliases of JSON documents (provenance records, file metadata, run descriptions).

A JSON object's values are of any JSON type, so ``Any`` is the honest value type; naming it
once here keeps ``Any`` out of the public signatures and says why.
"""

from __future__ import annotations

from typing import Any, TypeAlias

__all__ = ["JsonDict"]

JsonDict: TypeAlias = dict[str, Any]
"""A JSON object: string keys, values of any JSON type (nested objects, arrays, numbers...)."""
