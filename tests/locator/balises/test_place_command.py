"""``locator place-balises``: the placement rule as a command, against hand arithmetic, its list
read back as ``locator balises --balises`` reads it, and its refusals."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

from locator.balises.balisefile import BaliseList
from locator.balises.placement import place_balises
from locator.cli import main
from locator.odometry.confidence import OdometerAccuracy
from locator.odometry.odometer import OdometerConfig
from predisat.track import demo_track

TRAILER = OdometerAccuracy.from_config(OdometerConfig.trailer_axle_with_radar())


def test_place_balises_keeps_the_placeable_candidates_and_reads_back(tmp_path, capsys):
    """Demo line 0-3 km, a balise every 120 m, an outage 1000-2400 m, the trailer axle's bounds
    (1 m + 4.007 %), entry reach 25.6 m: a candidate at b in the outage predicts
    ceil(25.6 + 1 + 4.007 % x max(b - 1000, 2400 - b) + 1 m); 63 m holds from 1517 to 1883 m."""
    out, table = tmp_path / "placed.csv", tmp_path / "all.csv"
    rc = main(["place-balises", "--from-km", "0", "--to-km", "3", "--outage", "1000", "2400",
               "--out", str(out), "--table", str(table)])  # fmt: skip
    assert rc == 0
    printed = capsys.readouterr().out
    assert "26 candidates every 120 m" in printed and "outages 1000-2400 m" in printed
    assert "not placeable: 1080-1440 m (predicted accuracy up to 81 m > 63 m)" in printed
    assert "not placeable: 1920-2400 m (predicted accuracy up to 84 m > 63 m)" in printed
    b = 120.0 * np.arange(26)
    d = np.where((b >= 1000.0) & (b <= 2400.0), np.maximum(b - 1000.0, 2400.0 - b), 0.0)
    q = np.where(d > 0, np.ceil(25.6 + 1.0 + TRAILER.over_rel * d + 1.0 - 1e-9), 27.0)
    every = pd.read_csv(table)
    np.testing.assert_allclose(every["predicted_q_m"], q)
    assert every["placeable"].tolist() == (q <= 63.0).tolist()
    # the list is the one `locator balises --balises` reads, ids kept from the candidates
    placed = BaliseList.from_csv(out, demo_track())
    assert placed.chainage_m.tolist() == b[q <= 63.0].tolist()
    assert placed.ids == tuple(f"VB{k:05d}" for k in np.flatnonzero(q <= 63.0))
    assert placed.q_reference.all() and (placed.accuracy_m == 1.0).all()


def test_a_better_odometer_or_a_smaller_gate_changes_what_is_placed(tmp_path, capsys):
    base = ["place-balises", "--from-km", "0", "--to-km", "3", "--outage", "1000", "2400"]
    assert main([*base, "--odometer-accuracy", "1", "0.005", "0.005",
                 "--out", str(tmp_path / "a.csv")]) == 0  # fmt: skip
    assert len(pd.read_csv(tmp_path / "a.csv")) == 26  # 25.6 + 1 + 0.5 % x 1400 + 1: 35 m
    capsys.readouterr()
    # 40 m: 27 m outside the outage, at least 25.6 + 1 + 4.007 % x 700 + 1 = 56 m inside it
    assert main([*base, "--max-locacc", "40", "--out", str(tmp_path / "b.csv")]) == 0
    assert "not placeable: 1080-2400 m (predicted accuracy up to 84 m > 40 m)" in (
        capsys.readouterr().out)
    assert len(pd.read_csv(tmp_path / "b.csv")) == 26 - 12


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--outage", "2400", "1000"], r"--outage 2400 1000: START_M must be below END_M"),
        (["--outage", "0", "3000", "--entry-reach", "40"],
         r"no candidate is placeable between 0 and 3000 m .*--entry-reach.*"
         r"--odometer-accuracy"),
        (["--accuracy", "63"], r"--accuracy 63: a balise surveyed to 63 m can never"),
    ],
)
def test_refusals_name_the_option_and_the_fix(tmp_path, capsys, extra, match):
    assert main(["place-balises", "--from-km", "0", "--to-km", "3", *extra,
                 "--out", str(tmp_path / "x.csv")]) == 2  # fmt: skip
    assert re.search(match, capsys.readouterr().err)
    assert not (tmp_path / "x.csv").exists()
    assert main(["place-balises", "--from-km", "0", "--to-km", "0.05",
                 "--out", str(tmp_path / "x.csv")]) == 2  # fmt: skip
    assert "shorter than --spacing 120 m" in capsys.readouterr().err


def test_odometer_accuracy_in_percent_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["place-balises", "--odometer-accuracy", "5", "5", "5",
              "--out", str(tmp_path / "x.csv")])  # fmt: skip
    assert "give a fraction" in capsys.readouterr().err


def test_place_balises_guards():
    track = demo_track()
    with pytest.raises(ValueError, match="max_locacc_m 70 must lie in"):
        place_balises(track, 0.0, 1000.0, 100.0, [], TRAILER, 25.0, max_locacc_m=70.0)
    with pytest.raises(ValueError, match="accuracy_m 63 must lie in"):
        place_balises(track, 0.0, 1000.0, 100.0, [], TRAILER, 25.0, accuracy_m=63.0)


@pytest.mark.parametrize("outages", [[(1000.0, 1300.0), (1250.0, 1600.0)],
                                     [(1250.0, 1600.0), (1000.0, 1300.0)],
                                     [(1000.0, 1300.0), (1300.0, 1600.0)]])
def test_overlapping_or_touching_outages_are_one_outage(outages):
    """A tunnel given in two pieces, or a map's tunnel and an --outage over its approach: no
    satellite between them resets the reach. Each taken from its own portals predicted 48 m
    at 1100 m inside 1000-1600 m (1 m + 10 %, entry 25.6 m), placeable; the joined outage's
    78 m is not (m8)."""
    from locator.balises.placement import placement_check
    from locator.odometry.confidence import OdometerAccuracy

    acc = OdometerAccuracy(1.0, 0.1, 0.1)
    q, ok = placement_check([1100.0, 1500.0], [1.0, 1.0], outages, acc, 25.6)
    q1, _ = placement_check([1100.0, 1500.0], [1.0, 1.0], [(1000.0, 1600.0)], acc, 25.6)
    np.testing.assert_array_equal(q, q1)
    assert not ok.any() and q[0] == 78.0


@pytest.mark.parametrize(("extra", "said"), [
    (["--prefix", "a,b"], "--prefix 'a,b'"),  # written, then refused by `locator balises`
    (["--outage", "1000000", "2400000"], "--outage 1e+06 2.4e+06"),  # off the map: ignored
])
def test_place_balises_refuses_what_it_would_write_wrong(tmp_path, capsys, extra, said):
    """A prefix with a comma wrote ids that BaliseList.from_csv refuses; an outage past the
    map's end (millimetres, another line) placed every candidate without a word (m8)."""
    out = tmp_path / "p.csv"
    assert main(["place-balises", "--from-km", "0", "--to-km", "3", *extra,
                 "--out", str(out)]) == 2  # fmt: skip
    assert said in capsys.readouterr().err
    assert not out.exists()


def test_place_balises_warns_of_an_outage_shorter_than_a_train(tmp_path, capsys) -> None:
    # km typed where metres are read: written (it may be meant), but said (m8)
    out = tmp_path / "p.csv"
    assert main(["place-balises", "--from-km", "0", "--to-km", "3", "--outage", "1", "2.4",
                 "--out", str(out)]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert "1.40 m long" in err and "--outage 1000 2400" in err and out.exists()
