"""Balise lists: generation, round trip, bad files (locator.balises.balisefile)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from locator.balises.balisefile import BaliseFileError, BaliseList
from tests.locator._scene import straight_path


@pytest.fixture(scope="module")
def track():
    return straight_path(heading_deg=60.0, length_m=2000.0).track


def test_along_track_round_trip(tmp_path, track):
    bl = BaliseList.along_track(track, 100.0, 1000.0, 120.0)
    assert len(bl) == 8 and np.all(np.diff(bl.chainage_m) == 120.0)
    back = BaliseList.from_csv(bl.to_csv(tmp_path / "b.csv"), track)
    assert back.ids == bl.ids and back.telegram == bl.telegram
    np.testing.assert_array_equal(back.chainage_m, bl.chainage_m)
    np.testing.assert_array_equal(back.lat_deg, bl.lat_deg)
    assert back.q_reference.all()


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda df: df.drop(columns="telegram"), "missing columns"),
        (
            lambda df: df.assign(id=["A", "B", "C", "B", "E"]),
            r"line 5: id 'B' already used on line 3",
        ),
        # ids told apart by case only, and an id with a (quoted) comma
        (
            lambda df: df.assign(id=["A", "VB1", "C", "vb1", "E"]),
            r"line 5: id 'vb1' already used on line 3 \(as 'VB1': case aside\)",
        ),
        (lambda df: df.assign(id=["A", "B", "C,D", "E", "F"]), r"line 4: id 'C,D' holds a comma"),
        (
            lambda df: df.assign(chainage_m=np.where(df.index == 4, 2500.0, df["chainage_m"])),
            r"line 6: balise .* off the track",
        ),
        (lambda df: df.iloc[[0, 2, 1, 3, 4]], r"line 4: balise .* does not follow"),
        (
            lambda df: df.assign(
                chainage_m=np.where(df.index == 2, df["chainage_m"] + 30.0, df["chainage_m"])
            ),
            r"line 4: balise .* coordinates are 30.0 m horizontally from the track",
        ),
        (
            lambda df: df.assign(h_m=np.where(df.index == 1, "", df["h_m"].astype(str))),
            r"line 3: h_m is empty or not a number",
        ),
        (
            lambda df: df.assign(h_m=np.where(df.index == 1, "x", df["h_m"].astype(str))),
            r"line 3: h_m 'x' is not a number; give the ellipsoidal height in metres",
        ),
        # a chainage 4.8 m from where its coordinates put it, stated to 0.5 m (a user trial's
        # list was accepted, the telegram's accuracy built on the 0.5 m)
        (
            lambda df: df.assign(
                chainage_m=np.where(df.index == 2, df["chainage_m"] + 4.8, df["chainage_m"]),
                accuracy_m=0.5,
            ),
            r"line 4: balise .* coordinates lie 4\.8 m along the track .* accuracy_m 0\.5",
        ),
        # an accuracy Q_LOCACC cannot state: the balise could never be captured (a user
        # trial's 70 m was a silent miss)
        (
            lambda df: df.assign(accuracy_m=np.where(df.index == 3, 70.0, 1.0)),
            r"line 5: balise .* accuracy_m 70 leaves nothing of the 63 m",
        ),
        # two balises sending one telegram: a receiver takes them for one (a user trial's
        # copied row, its id and position edited, was accepted)
        (
            lambda df: df.assign(telegram=np.where(df.index == 3, df["telegram"][1],
                                                   df["telegram"])),
            r"line 5: balise .* sends the telegram .* of balise .* on line 3",
        ),
        # an empty telegram is refused, as the format says
        (
            lambda df: df.assign(telegram=np.where(df.index == 2, "", df["telegram"])),
            r"line 4: balise .* has an empty telegram",
        ),
        # chainages in kilometres: the coordinates say where they belong
        (
            lambda df: df.assign(chainage_m=df["chainage_m"] / 1000.0),
            r"line 2: .*did you give kilometres\? its coordinates lie on the track at 100\.0 m",
        ),
        # one row in kilometres among metres: not "sort the rows" (a user trial)
        (
            lambda df: df.assign(
                chainage_m=np.where(df.index == 2, df["chainage_m"] / 1000.0, df["chainage_m"])
            ),
            r"line 4: balise .* chainage 0\.5 - did you give kilometres\? .* at 500\.0 m",
        ),
        (
            lambda df: df.rename(columns={"lat_deg": "lon_deg", "lon_deg": "lat_deg"}),
            r"line 2: .*lat_deg and lon_deg look swapped",
        ),
    ],
)
def test_bad_lists_name_the_line_and_the_fix(tmp_path, track, edit, match):
    bl = BaliseList.along_track(track, 100.0, 900.0, 200.0)
    p = tmp_path / "b.csv"
    bl.to_csv(p)
    edit(pd.read_csv(p)).to_csv(p, index=False)
    with pytest.raises(BaliseFileError, match=match) as exc:
        BaliseList.from_csv(p, track)
    assert str(p) in str(exc.value)


@pytest.mark.parametrize(
    ("rename", "meant"),
    [
        ({"accuracy_m": "accuracy"}, "accuracy_m"),
        ({"accuracy_m": "Q_LOCACC", "q_reference": "Q_REFERENCE"}, "q_reference"),
        ({"q_reference": "Q_REFERENCE"}, "q_reference"),
        ({"accuracy_m": "Accuracy_M"}, "accuracy_m"),
    ],
)
def test_an_optional_column_under_another_name_is_refused(tmp_path, track, rename, meant):
    """A user trial's list with ``accuracy`` (20 m) was read with the default 1 m, and the
    telegrams stated an accuracy about 20 m too tight."""
    bl = BaliseList.along_track(track, 100.0, 900.0, 200.0)
    p = tmp_path / "b.csv"
    bl.to_csv(p)
    pd.read_csv(p).assign(accuracy_m=20.0).rename(columns=rename).to_csv(p, index=False)
    with pytest.raises(BaliseFileError, match=rf"line 1: column .* is not read.*{meant!r}"):
        BaliseList.from_csv(p, track)
    # a column the list does not use under any name is left alone
    pd.read_csv(p).rename(columns={v: k for k, v in rename.items()}).assign(
        comment="x"
    ).to_csv(p, index=False)
    assert BaliseList.from_csv(p, track).accuracy_m.tolist() == [20.0] * 5


def test_heights_are_not_compared(tmp_path, track):
    # a track map without heights (h 0) and balises with their real ellipsoidal height: only
    # the horizontal offset counts
    bl = BaliseList.along_track(track, 100.0, 900.0, 200.0)
    p = bl.to_csv(tmp_path / "b.csv")
    pd.read_csv(p).assign(h_m=120.0).to_csv(p, index=False, float_format="%.17g")
    back = BaliseList.from_csv(p, track)
    np.testing.assert_array_equal(back.h_m, 120.0)
    # a horizontal offset of 6 m is still refused, whatever the height
    east = pd.read_csv(p)
    east.loc[1, "lon_deg"] += 6.0 / (111320.0 * np.cos(np.radians(east.loc[1, "lat_deg"])))
    east.to_csv(p, index=False, float_format="%.17g")
    with pytest.raises(BaliseFileError, match=r"line 3: .* 6\.0 m horizontally from the track"):
        BaliseList.from_csv(p, track)


def test_separators_and_binary_files(tmp_path, track):
    bl = BaliseList.along_track(track, 100.0, 900.0, 200.0)
    text = bl.to_csv(tmp_path / "b.csv").read_text()
    p = tmp_path / "spaces.csv"
    p.write_text(text.replace(",", ", "))  # spaces after the commas: read as the plain list
    back = BaliseList.from_csv(p, track)
    assert back.ids == bl.ids and back.telegram == bl.telegram
    p = tmp_path / "semicolon.csv"
    p.write_text(text.replace(",", ";"))
    with pytest.raises(BaliseFileError, match=r"line 1: the columns are separated by semicolons"):
        BaliseList.from_csv(p, track)
    # a trailing comma on every row (a spreadsheet export): read as the plain list, not shifted
    p = tmp_path / "trailing.csv"
    lines = text.splitlines()
    p.write_text("\n".join([lines[0], *(line + "," for line in lines[1:])]) + "\n")
    back = BaliseList.from_csv(p, track)
    assert back.ids == bl.ids and np.allclose(back.chainage_m, bl.chainage_m)
    # a column named twice: which one is meant cannot be told
    p = tmp_path / "twice.csv"
    head = lines[0].split(",")
    p.write_text("\n".join([",".join([*head, head[1]]),
                            *(line + "," + line.split(",")[1] for line in lines[1:])]) + "\n")
    with pytest.raises(BaliseFileError, match=rf"line 1: the header names \['{head[1]}'\] twice"):
        BaliseList.from_csv(p, track)
    # a thousands separator: the fix is said
    p = tmp_path / "thousands.csv"
    row = lines[1].split(",")
    row[1] = "1,234.5"  # a chainage with a thousands separator
    p.write_text("\n".join([lines[0], ",".join(row), *lines[2:]]) + "\n")
    with pytest.raises(BaliseFileError, match=r"thousands separator"):
        BaliseList.from_csv(p, track)
    # a comment line above the header or among the rows: named, not "8 fields where ..."
    for k, name in ((0, "comment_top.csv"), (3, "comment_mid.csv")):
        p = tmp_path / name
        p.write_text("\n".join([*lines[:k], "# balises of line 144, km 0.3-2.8", *lines[k:]]))
        with pytest.raises(BaliseFileError, match=rf"line {k + 1}: a comment line"):
            BaliseList.from_csv(p, track)
    p = tmp_path / "b.npz"
    np.savez_compressed(p, x=np.arange(1000.0))
    with pytest.raises(BaliseFileError, match=r"b\.npz, line \d+: byte 0x.. is not text"):
        BaliseList.from_csv(p, track)


def test_spreadsheet_line_ends_empty_rows_and_code_pages(tmp_path, track):
    """Excel's "CSV (Macintosh)" ends lines with CR alone (a traceback naming no file), saves
    formatted empty rows as ",,,", and a Windows code page for an accented name."""
    bl = BaliseList.along_track(track, 100.0, 900.0, 200.0)
    text = bl.to_csv(tmp_path / "b.csv").read_text()
    lines = text.splitlines()
    for name, content in (("cr.csv", "\r".join(lines) + "\r"),
                          ("crlf.csv", "\r\n".join(lines) + "\r\n"),
                          ("empty_rows.csv", text + ",,,,,\n,,,,,\n")):  # fmt: skip
        p = tmp_path / name
        p.write_bytes(content.encode())
        back = BaliseList.from_csv(p, track)
        assert back.ids == bl.ids and np.allclose(back.chainage_m, bl.chainage_m), name
    # a bad value on line 3 of a CR-only file is still named on line 3
    bad = [*lines]
    bad[2] = bad[2].replace(bad[2].split(",")[1], "x", 1)
    (tmp_path / "cr_bad.csv").write_bytes("\r".join(bad).encode())
    with pytest.raises(BaliseFileError, match=r"cr_bad\.csv, line 3"):
        BaliseList.from_csv(tmp_path / "cr_bad.csv", track)
    named = pd.read_csv(tmp_path / "b.csv").assign(comment="Gembloux–Ottignies")
    named.to_csv(tmp_path / "cp1252.csv", index=False, encoding="cp1252")
    with pytest.raises(BaliseFileError, match=r"line 2: byte 0x96 is not UTF-8.*save it as CSV "
                       "UTF-8"):  # fmt: skip
        BaliseList.from_csv(tmp_path / "cp1252.csv", track)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        # Belgian Lambert 72 metres in the degree columns: it fell through to the track
        # map's "enu_m contains NaN or infinite values", no file, line or fix
        (
            lambda df, L: df.assign(lat_deg=139422.56, lon_deg=173412.76),
            r"line 2: lat_deg 139423 is no latitude .*Lambert 72",
        ),
        (
            lambda df, L: df.assign(lon_deg=df["lon_deg"] + 200.0),
            r"line 2: lon_deg .* is no longitude",
        ),
        # chainage measured from the other end, rows in their order (decreasing) or sorted
        (
            lambda df, L: df.assign(chainage_m=L - df["chainage_m"]),
            r"line 2: .*chainages decrease .*from the other end",
        ),
        (
            lambda df, L: df.assign(chainage_m=L - df["chainage_m"]).iloc[::-1],
            r"line 2: .*from the other end\? its coordinates lie on the track at 900\.0 m",
        ),
    ],
)
def test_coordinates_and_chainages_of_another_convention(tmp_path, track, edit, match):
    bl = BaliseList.along_track(track, 100.0, 900.0, 200.0)
    p = tmp_path / "b.csv"
    bl.to_csv(p)
    edit(pd.read_csv(p), track.length_m).to_csv(p, index=False)
    with pytest.raises(BaliseFileError, match=match):
        BaliseList.from_csv(p, track)
