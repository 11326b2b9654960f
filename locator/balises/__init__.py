"""Virtual balises (source document 001): the stored list, capture on the fused interval, the
placement rule, the ``locator balises`` job. See ``docs/odometry.md``.
"""

from locator.balises.balisefile import BaliseFileError, BaliseList
from locator.balises.capture import EMIT_MODES, CaptureConfig, capture_balises, score_captures
from locator.balises.placement import place_balises, placement_check, predicted_reach_m

__all__ = [
    "EMIT_MODES",
    "BaliseFileError",
    "BaliseList",
    "CaptureConfig",
    "capture_balises",
    "place_balises",
    "placement_check",
    "predicted_reach_m",
    "score_captures",
]
