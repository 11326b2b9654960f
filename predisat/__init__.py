"""PREDISAT: camera-surveyed GNSS elevation masks along railway lines.

The batch pipeline turns 45-degree side-camera frames taken along a line into per-position
elevation masks, and evaluates which satellites a train may trust. See ``README.md`` and
``docs/`` for formats and methods.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("predisat")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
