"""The error model's use by `locator run` and `locator balises` (locator.modelcheck)."""

from __future__ import annotations

import itertools

import numpy as np

from locator.fde import LocatorConfig
from locator.modelcheck import deepest_k
from predisat.gnss.errormodel import ErrorModel, IntervalModel
from predisat.gnss.integrity import IntegrityBudget


def test_deepest_k_is_the_widest_k_any_claimed_union_may_use() -> None:
    """Active integrity drops blunt pairs from a union of 4-5 satellites and widens the rest
    to the ``k`` of their disjoint pairs (``LocatorConfig.k_sigma_for``): over every subset of
    the pairs of 5 satellites, the widest is what a model must have been checked to."""
    for risk in (1e-12, 1e-7):
        cfg = LocatorConfig(budget=IntegrityBudget(risk))
        pairs = list(itertools.combinations(range(5), 2))
        widest = max(
            cfg.k_sigma_for(np.array(sub))
            for r in range(1, len(pairs) + 1)
            for sub in itertools.combinations(pairs, r)
        )
        assert deepest_k(cfg) == widest
        assert widest > IntegrityBudget(risk).k_sigma(2)  # more than the mode's nominal k
    fixed = LocatorConfig(model=IntervalModel(ErrorModel(), 2.5), budget=None)
    assert deepest_k(fixed) == 2.5


def test_a_simulation_profile_lists_the_systems_received_not_every_one_carried():
    """A review: a pooled calibration covers only the systems that gave residuals, so a run of
    the same simulation with --constellation all (QZSS carried, never received) made no claim,
    'system J was not calibrated'."""
    from types import SimpleNamespace

    import numpy as np

    from locator.modelcheck import sim_profile

    sats = ("G01", "G02", "J01", "E05")
    received = np.array([[1, 1, 0, 0], [1, 0, 0, 1]], bool)
    sim = SimpleNamespace(sats=sats, received=received)
    assert sorted(sim_profile(sim, "all").codes) == ["E", "G"]
    assert sorted(sim_profile(sim, "gps").codes) == ["G"]
