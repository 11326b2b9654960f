"""The checks every epoch source makes of the odometer it is given."""

from __future__ import annotations

import numpy as np
import pytest

from locator.sources import check_odometer


def test_an_odometer_with_one_value_per_epoch_and_its_disputed_distance_pass() -> None:
    odo = np.arange(5.0)
    extra = np.column_stack([np.linspace(0, 1, 5), np.zeros(5)])
    check_odometer(odo, extra, 5)
    check_odometer(odo, None, 5)
    check_odometer(None, None, 5)


@pytest.mark.parametrize(
    ("odometer", "extra", "message"),
    [
        (np.arange(4.0), None, r"one value per epoch \(\(5,\)\), got \(4,\)"),
        (np.zeros((5, 1)), None, r"one value per epoch"),
        (None, np.zeros((5, 2)), "needs odometer"),
        (np.arange(5.0), np.zeros((5, 3)), r"shape \(5, 2\), got \(5, 3\)"),
        (np.arange(5.0), np.array([[0, 0], [1, 0], [0.5, 0], [2, 0], [3, 0]]), "non-decreasing"),
        (np.arange(5.0), np.full((5, 2), -1.0), ">= 0"),
        (np.arange(5.0), np.full((5, 2), np.nan), "finite"),
    ],
)
def test_a_bad_odometer_is_refused_naming_the_problem(
    odometer: np.ndarray | None, extra: np.ndarray | None, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        check_odometer(odometer, extra, 5)
