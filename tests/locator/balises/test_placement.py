"""The placement rule's predicted reach against hand arithmetic (locator.balises.placement)."""

from __future__ import annotations

import numpy as np
import pytest

from locator.balises.placement import placement_check, predicted_reach_m
from locator.odometry.confidence import OdometerAccuracy


def test_reach_grows_from_the_portal_entered_worst_of_both_directions():
    acc = OdometerAccuracy(1.0, 0.035, 0.032)
    # a tunnel 1000-1400 m; a balise 100 m inside the 1000 m portal is 300 m from the other:
    # the train entering at 1400 m has run 300 m without satellites: 20 + 1 + 3.5 % x 300
    b = [500.0, 1100.0, 1200.0, 1399.0]
    r = predicted_reach_m(b, [(1000.0, 1400.0)], acc, 20.0)
    np.testing.assert_allclose(r, [20.0, 31.5, 28.0, 21.0 + 0.035 * 399.0])


def test_placeable_only_where_the_stated_accuracy_fits_q_locacc():
    acc = OdometerAccuracy(1.0, 0.035, 0.032)
    # in a 2400 m tunnel the middle is 1200 m from either portal: 25 + 1 + 42 = 68 m + 1 m
    q, ok = placement_check([0.0, 3200.0, 4000.0], [1.0, 1.0, 1.0], [(2800.0, 5200.0)], acc,
                            25.0)  # fmt: skip
    assert q.tolist() == [26.0, 27.0 + np.ceil(0.035 * 2000.0), 69.0]
    assert ok.tolist() == [True, False, False]
    # an odometer with 0.5 % bounds keeps the whole tunnel placeable: 25 + 1 + 0.5 % x 2400
    q, ok = placement_check([4000.0, 5199.0], [1.0, 1.0], [(2800.0, 5200.0)],
                            OdometerAccuracy(1.0, 0.005, 0.005), 25.0)  # fmt: skip
    assert q.tolist() == [33.0, np.ceil(27.0 + 0.005 * 2399.0)]
    assert ok.all()


def test_guards():
    acc = OdometerAccuracy()
    with pytest.raises(ValueError, match="start must be below end"):
        predicted_reach_m([1.0], [(5.0, 5.0)], acc, 10.0)
    with pytest.raises(ValueError, match="entry_reach_m"):
        predicted_reach_m([1.0], [], acc, -1.0)
