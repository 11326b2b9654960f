"""Frozen records hold read-only arrays that no caller's array shares: a write through a field
or a result, or a caller reusing its buffer, cannot change a record, a cache or another
record (a code-health review, 2026-12-06, found each case below changing results)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from predisat.readonly import freeze_array_fields, readonly_array

DATA = Path(__file__).resolve().parents[1] / "data"


def test_a_writeable_array_is_copied_and_the_callers_left_writeable() -> None:
    a = np.arange(5.0)
    b = readonly_array(a)
    assert not b.flags.writeable and not np.shares_memory(a, b)
    assert a.flags.writeable  # the caller's array is not made read-only behind its back
    assert readonly_array(b) is b  # read-only all the way down: kept, no copy
    assert readonly_array(b[1:]).base is not None  # a view of it too


def test_a_read_only_view_of_writeable_memory_is_copied() -> None:
    a = np.arange(5.0)
    view = a.view()
    view.setflags(write=False)
    out = readonly_array(view)
    a[:] = -1.0
    assert out.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]


def test_a_conversion_is_not_copied_twice_and_never_aliases() -> None:
    i = np.arange(3)
    f = readonly_array(i, np.float64)
    assert f.dtype == np.float64 and not f.flags.writeable and not np.shares_memory(i, f)
    assert not readonly_array([1, 2]).flags.writeable


def test_freeze_array_fields_replaces_only_arrays() -> None:
    @dataclass(frozen=True)
    class Rec:
        x: NDArray
        name: str

        def __post_init__(self) -> None:
            freeze_array_fields(self)

    buf = np.zeros(3)
    rec = Rec(buf, "r")
    buf[:] = 7.0
    assert rec.x.tolist() == [0.0, 0.0, 0.0] and rec.name == "r"
    with pytest.raises(ValueError, match="read-only"):
        rec.x[0] = 1.0
    with pytest.raises(TypeError, match="dataclass instance"):
        freeze_array_fields(Rec)


def test_a_navigation_column_cannot_be_written_into_the_records() -> None:
    from predisat.gnss.ephemeris import Ephemeris

    eph = Ephemeris.from_rinex(DATA / "gnss" / "brdc1820_G01G02G05.10n")
    t = np.arange(3) * 900.0 + float(np.nanmedian(eph.kepler.epoch_gps_s))
    health = eph.kepler.col("health")
    with pytest.raises(ValueError, match="read-only"):
        health[:] = 1.0
    assert np.isfinite(eph.evaluate(t)[0][..., 0]).sum() > 0


def test_an_ephemeris_status_keeps_its_own_epochs() -> None:
    from predisat.gnss.ephemeris import Ephemeris

    prec = Ephemeris.from_sp3(DATA / "gnss" / "igs15904_G01G02G05.sp3")
    epochs = np.array(prec.sp3.epochs_gps_s[10:13])  # the caller's writeable buffer
    before = prec.evaluate(epochs)[0]
    status = prec.status(epochs)
    epochs += 3600.0  # the caller moves on to the next hour
    assert not np.shares_memory(status.gps_s, epochs)
    assert not status.gps_s.flags.writeable and not prec.sp3.epochs_gps_s.flags.writeable
    np.testing.assert_array_equal(prec.evaluate(epochs - 3600.0)[0], before)


def test_a_selection_is_not_changed_by_the_callers_next_epoch() -> None:
    from locator.selection import select_satellites
    from predisat.masks.maskset import MaskSet

    ch = np.linspace(0, 100, 11)
    ms = MaskSet.from_arrays(ch, np.full(11, 50.0), np.full(11, 4.0), np.zeros(11),
                             np.zeros(11), np.full((11, 72), 10.0))  # fmt: skip
    el = np.array([[5.0, 20.0, 40.0]])
    sel = select_satellites(ms, np.array([40.0]), np.array([60.0]), np.array([[0.0, 90, 180]]),
                            el, sats=("G01", "G02", "G03"))  # fmt: skip
    el[:] = 50.0
    assert sel.el_deg.tolist() == [[5.0, 20.0, 40.0]] and sel.trusted.tolist() == [
        [False, True, True]
    ]


def test_the_cached_pair_table_cannot_be_corrupted_by_a_caller() -> None:
    from predisat.availability.interval import matching_table, three_independent_pairs

    rng = np.random.default_rng(4)
    g, s = rng.uniform(0.2, 1.0, (4, 8)), rng.uniform(1.0, 3.0, (4, 8))
    before = three_independent_pairs(g, s)[0]
    i, j, sets = matching_table(8)
    for arr in (i, j, sets):
        with pytest.raises(ValueError, match="read-only"):
            arr[:] = 0
    np.testing.assert_array_equal(three_independent_pairs(g, s)[0], before)
