"""The 1-D track-constrained GNSS locator (SATHIA) with mask-aware satellite selection."""

__all__: list[str] = []
