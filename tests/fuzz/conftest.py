"""Hypothesis profiles of the reader fuzzing: ``ci`` (default, the whole of tests/fuzz in
well under 30 s, the same inputs every run) and ``long`` (``PREDISAT_FUZZ_PROFILE=long``).
The large budget is ``scripts/fuzz_readers.py`` (docs/fuzzing.md)."""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

_SLOW = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much]
settings.register_profile(
    "ci", max_examples=40, deadline=None, derandomize=True, suppress_health_check=_SLOW,
    database=None,
)  # fmt: skip
settings.register_profile(
    "long", max_examples=5000, deadline=None, suppress_health_check=_SLOW
)
settings.load_profile(os.environ.get("PREDISAT_FUZZ_PROFILE", "ci"))
