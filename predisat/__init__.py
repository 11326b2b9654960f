"""PREDISAT: camera-surveyed GNSS elevation masks along railway lines.

The batch pipeline turns 45-degree side-camera frames taken along a line into per-position
elevation masks, and evaluates which satellites a train may trust. See ``README.md`` and
``docs/`` for formats and methods.
"""

import os
from importlib.metadata import PackageNotFoundError, version

# An empty SOURCE_DATE_EPOCH means "not pinned" (predisat.clock), but numpy's f2py, which
# scipy.special imports, reads it with int() at import: every command crashed, and a cluster's
# workers could not load a task and left the run waiting (a user trial). Unset, as meant.
if not os.environ.get("SOURCE_DATE_EPOCH", "x").strip():
    del os.environ["SOURCE_DATE_EPOCH"]

try:
    __version__ = version("predisat")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
