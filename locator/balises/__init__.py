"""Virtual balises (source document 001): the stored list, capture on the fused interval, the
``locator balises`` job. See ``docs/odometry.md``.
"""

from locator.balises.balisefile import BaliseFileError, BaliseList
from locator.balises.capture import EMIT_MODES, CaptureConfig, capture_balises, score_captures

__all__ = [
    "EMIT_MODES",
    "BaliseFileError",
    "BaliseList",
    "CaptureConfig",
    "capture_balises",
    "score_captures",
]
