"""Tests for predisat.masks.fileformat: mask file v1 (GeoParquet) and the exporters.

Files are read back with independent parsers (pyarrow + struct for WKB, numpy.loadtxt, a
Python transcription of RTKLIB's documented readelmask rules) and compared with brute-force
values computed here from the documented rules.
"""

from __future__ import annotations

import csv
import json
import math
import re
import struct

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import shapely

from predisat.masks.fileformat import (
    FORMAT_NAME,
    METADATA_KEY,
    MaskFileError,
    read_masks,
    to_pvgis_horizon,
    to_rtklib_mask,
    to_urbannav_csv,
    write_masks,
)
from predisat.masks.maskset import BinSource, MaskError, MaskSet


def make_set(n_pos=12, step=1.0, seed=0, margin=None):
    rng = np.random.default_rng(seed)
    n_az = round(360 / step)
    ch = 250.0 + 10.0 * np.arange(n_pos) + rng.uniform(-2, 2, n_pos)
    src = rng.integers(0, 3, (n_pos, n_az))
    mask = rng.uniform(0.0, 75.0, (n_pos, n_az))
    mask[src == BinSource.ASSUMED] = 30.0
    left = rng.uniform(3, 30, n_pos)
    left[min(2, n_pos - 1)] = np.nan
    return MaskSet.from_arrays(
        ch,
        50.62 + 1e-4 * np.arange(n_pos),
        4.45 - 1e-4 * np.arange(n_pos),
        rng.uniform(100, 120, n_pos),
        rng.uniform(0, 360, n_pos),
        mask,
        az_step_deg=step,
        source=src,
        margin_deg=rng.uniform(0, 2, (n_pos, n_az)) if margin is None else margin,
        descriptors={
            "left_obstacle_distance_m": left,
            "left_obstacle_height_m": rng.uniform(0, 10, n_pos),
            "catenary_mast_distance_m": rng.uniform(2, 4, n_pos),
        },
        provenance={"survey": "demo-001", "parameters": {"sky": {"threshold": 0.4}}},
    )


def brute_window_max(row, step, a, w):
    """Max over bins whose closed interval meets the closed window [a - w, a + w] (circular)."""
    best = -np.inf
    for k, v in enumerate(row):
        d = abs((k * step - a + 180.0) % 360.0 - 180.0)
        if d <= w + step / 2 + 1e-12:
            best = max(best, float(v))
    return best


# ---------------------------------------------------------------- GeoParquet round trip
@pytest.mark.parametrize("step", [1.0, 0.5])
def test_round_trip_is_exact(tmp_path, step):
    m = make_set(step=step)
    path = write_masks(m, tmp_path / "line.masks.parquet")
    back = read_masks(path)
    assert back.equals(m)
    assert np.isnan(back.descriptors["left_obstacle_distance_m"][2])
    assert back.provenance["parameters"]["sky"]["threshold"] == 0.4
    assert [p.name for p in tmp_path.iterdir()] == ["line.masks.parquet"]  # no temp left


def test_overwrite_replaces_the_file(tmp_path):
    path = tmp_path / "m.parquet"
    write_masks(make_set(seed=1), path)
    m2 = make_set(seed=2, n_pos=5)
    write_masks(m2, path)
    assert read_masks(path).equals(m2)


def test_write_into_missing_folder_names_it(tmp_path):
    with pytest.raises(MaskFileError, match="does not exist"):
        write_masks(make_set(), tmp_path / "nope" / "m.parquet")


def test_file_is_geoparquet_readable_by_pyarrow_alone(tmp_path):
    m = make_set()
    path = write_masks(m, tmp_path / "m.parquet")
    table = pq.read_table(path, page_checksum_verification=True)  # as the docs say
    meta = table.schema.metadata
    geo = json.loads(meta[b"geo"])
    assert geo["version"] in ("1.0.0", "1.1.0")
    assert geo["primary_column"] == "geometry"
    col = geo["columns"]["geometry"]
    assert col["encoding"] == "WKB" and col["geometry_types"] == ["Point"]
    assert col["crs"]["id"] == {"authority": "OGC", "code": "CRS84"}
    axes = [a["direction"] for a in col["crs"]["coordinate_system"]["axis"]]
    assert axes == ["east", "north"]  # x = longitude, y = latitude
    bbox = col["bbox"]
    assert bbox == pytest.approx(
        [m.lon_deg.min(), m.lat_deg.min(), m.lon_deg.max(), m.lat_deg.max()]
    )

    header = json.loads(meta[METADATA_KEY])
    assert header["format"] == FORMAT_NAME and header["format_version"] == 1
    assert header["az_step_deg"] == 1.0 and header["n_az"] == 360
    assert header["provenance"]["survey"] == "demo-001"

    # WKB decoded by hand: byte order 1 (little endian), type 1 (Point), x, y doubles
    for i, blob in enumerate(table.column("geometry").to_pylist()):
        order, gtype, x, y = struct.unpack("<BIdd", blob)
        assert (order, gtype) == (1, 1)
        assert (x, y) == (m.lon_deg[i], m.lat_deg[i])
    pts = shapely.from_wkb(table.column("geometry").to_numpy(zero_copy_only=False))
    np.testing.assert_array_equal(shapely.get_y(pts), m.lat_deg)

    df = table.to_pandas()
    np.testing.assert_array_equal(df["chainage_m"], m.chainage_m)
    np.testing.assert_array_equal(np.stack(df["mask_el_deg"].to_numpy()), m.mask_el_deg)
    np.testing.assert_array_equal(np.stack(df["source"].to_numpy()), m.source)
    assert (df["assumed_bins"] == (m.source == 2).sum(axis=1)).all()


def test_geopandas_reads_points_and_crs(tmp_path):
    # an independent reader (GeoParquet "geo" metadata, WKB, CRS); a dev dependency only
    gpd = pytest.importorskip("geopandas")
    m = make_set()
    path = write_masks(m, tmp_path / "m.parquet")
    gdf = gpd.read_parquet(path)
    assert gdf.crs is not None and gdf.crs.equals("OGC:CRS84")
    np.testing.assert_allclose(gdf.geometry.x, m.lon_deg)
    np.testing.assert_allclose(gdf.geometry.y, m.lat_deg)


# ---------------------------------------------------------------- validation on read
def _rewrite(src, dst, table=None, header_change=None, drop_header=False):
    table = pq.read_table(src) if table is None else table
    meta = dict(table.schema.metadata)
    if drop_header:
        del meta[METADATA_KEY]
    if header_change:
        header = json.loads(meta[METADATA_KEY])
        header.update(header_change)
        meta[METADATA_KEY] = json.dumps(header).encode()
    pq.write_table(table.replace_schema_metadata(meta), dst)
    return dst


def _replace_column(table, name, values):
    i = table.column_names.index(name)
    return table.set_column(i, name, values)


@pytest.fixture
def good_file(tmp_path):
    return write_masks(make_set(), tmp_path / "good.parquet")


def test_wrong_version_names_file_and_fix(good_file, tmp_path):
    bad = _rewrite(good_file, tmp_path / "v4.parquet", header_change={"format_version": 4})
    with pytest.raises(MaskFileError) as err:
        read_masks(bad)
    msg = str(err.value)
    assert "v4.parquet" in msg and "format_version 4" in msg and "upgrade" in msg


def _with_support(ms, seed=1):
    sup = np.random.default_rng(seed).integers(0, 256, ms.mask_el_deg.shape)
    return MaskSet.from_arrays(
        ms.chainage_m, ms.lat_deg, ms.lon_deg, ms.h_m, ms.heading_deg, ms.mask_el_deg,
        az_step_deg=ms.az_step_deg, source=ms.source, margin_deg=ms.margin_deg,
        descriptors=ms.descriptors, provenance=ms.provenance, support=sup,
    ), sup


def test_support_round_trip_is_version_3(tmp_path):
    ms, sup = _with_support(make_set())
    path = write_masks(ms, tmp_path / "s.parquet")
    table = pq.read_table(path)
    header = json.loads(table.schema.metadata[METADATA_KEY])
    assert header["format_version"] == 3 and "support" in header["columns"]
    # read with pyarrow alone: uint8 lists of n_az per row, the values given
    col = table.column("support").combine_chunks()
    assert pa.types.is_fixed_size_list(col.type) and col.type.value_type == pa.uint8()
    raw = np.asarray(col.flatten().to_numpy()).reshape(ms.n_pos, ms.n_az)
    assert np.array_equal(raw, sup)
    back = read_masks(path)
    assert back.support is not None and back.support.dtype == np.uint8
    assert np.array_equal(back.support, sup) and back.equals(ms)


def test_files_without_support_read_with_none(tmp_path):
    plain = write_masks(make_set(), tmp_path / "v1.parquet")
    assert json.loads(pq.read_schema(plain).metadata[METADATA_KEY])["format_version"] == 1
    assert "support" not in pq.read_table(plain).column_names
    assert read_masks(plain).support is None


def test_version_3_without_support_column_names_it(tmp_path):
    ms, _ = _with_support(make_set())
    path = write_masks(ms, tmp_path / "s.parquet")
    table = pq.read_table(path)
    bad = _rewrite(path, tmp_path / "nosup.parquet", table=table.drop_columns(["support"]))
    with pytest.raises(MaskFileError, match=r"nosup\.parquet.*missing column.*'support'"):
        read_masks(bad)


def test_support_out_of_range_or_not_integer_rejected():
    ms = make_set(n_pos=3)
    base = dict(az_step_deg=ms.az_step_deg, source=ms.source)
    args = (ms.chainage_m, ms.lat_deg, ms.lon_deg, ms.h_m, ms.heading_deg, ms.mask_el_deg)
    bad = np.zeros(ms.mask_el_deg.shape, int)
    bad[1, 7] = 300
    with pytest.raises(MaskError, match=r"support\[1, 7\] \(row, bin\).*\[0, 255\]"):
        MaskSet.from_arrays(*args, **base, support=bad)
    with pytest.raises(MaskError, match="support"):
        MaskSet.from_arrays(*args, **base, support=np.full(ms.mask_el_deg.shape, 1.5))
    with pytest.raises(MaskError, match="support has shape"):
        MaskSet.from_arrays(*args, **base, support=np.zeros((2, ms.n_az), int))


def test_wrong_format_and_missing_header(good_file, tmp_path):
    bad = _rewrite(good_file, tmp_path / "f.parquet", header_change={"format": "other"})
    with pytest.raises(MaskFileError, match="'other'"):
        read_masks(bad)
    bad = _rewrite(good_file, tmp_path / "h.parquet", drop_header=True)
    with pytest.raises(MaskFileError, match="not a PREDISAT mask file"):
        read_masks(bad)


def test_missing_column_is_named(good_file, tmp_path):
    table = pq.read_table(good_file).drop_columns(["heading_deg"])
    bad = _rewrite(good_file, tmp_path / "c.parquet", table=table)
    with pytest.raises(MaskFileError) as err:
        read_masks(bad)
    assert "c.parquet" in str(err.value) and "heading_deg" in str(err.value)


def test_bad_bin_count_names_column_and_row(good_file, tmp_path):
    table = pq.read_table(good_file)
    rows = table.column("mask_el_deg").to_pylist()
    rows[3] = rows[3][:-1]
    table = _replace_column(table, "mask_el_deg", pa.array(rows, type=pa.list_(pa.float32())))
    bad = _rewrite(good_file, tmp_path / "s.parquet", table=table)
    with pytest.raises(MaskFileError) as err:
        read_masks(bad)
    msg = str(err.value)
    assert "s.parquet" in msg and "'mask_el_deg'" in msg and "row 3" in msg and "359" in msg


def test_non_monotonic_chainage_names_row(good_file, tmp_path):
    table = pq.read_table(good_file)
    ch = table.column("chainage_m").to_numpy().copy()
    ch[5] = ch[3]
    table = _replace_column(table, "chainage_m", pa.array(ch))
    bad = _rewrite(good_file, tmp_path / "n.parquet", table=table)
    with pytest.raises(MaskFileError) as err:
        read_masks(bad)
    msg = str(err.value)
    assert "n.parquet" in msg and "chainage_m" in msg and "row 5" in msg


def test_elevation_out_of_range_names_row_and_bin(good_file, tmp_path):
    table = pq.read_table(good_file)
    mask = np.stack(table.column("mask_el_deg").to_numpy(zero_copy_only=False))
    mask[4, 7] = 95.0
    arr = pa.FixedSizeListArray.from_arrays(pa.array(mask.ravel(), pa.float32()), 360)
    bad = _rewrite(
        good_file, tmp_path / "r.parquet", table=_replace_column(table, "mask_el_deg", arr)
    )
    with pytest.raises(MaskFileError) as err:
        read_masks(bad)
    msg = str(err.value)
    assert "r.parquet" in msg and "mask_el_deg[4, 7]" in msg and "[0, 90]" in msg


def test_null_and_edited_geometry_are_rejected(good_file, tmp_path):
    table = pq.read_table(good_file)
    h = table.column("h_m").to_pylist()
    h[6] = None
    bad = _rewrite(
        good_file,
        tmp_path / "null.parquet",
        table=_replace_column(table, "h_m", pa.array(h, pa.float64())),
    )
    with pytest.raises(MaskFileError, match="'h_m' row 6 is null"):
        read_masks(bad)
    geoms = table.column("geometry").to_pylist()
    geoms[2] = shapely.to_wkb(shapely.points(0.0, 0.0))
    bad = _rewrite(
        good_file,
        tmp_path / "geom.parquet",
        table=_replace_column(table, "geometry", pa.array(geoms, pa.binary())),
    )
    with pytest.raises(MaskFileError, match="'geometry' row 2"):
        read_masks(bad)


def test_not_a_parquet_file(tmp_path):
    txt = tmp_path / "x.parquet"
    txt.write_text("hello")
    with pytest.raises(MaskFileError, match=r"not a readable Parquet.*predisat process"):
        read_masks(txt)
    with pytest.raises(MaskFileError, match="no such mask file"):
        read_masks(tmp_path / "missing.parquet")


def test_reads_the_output_folder_of_process(tmp_path):
    m = make_set()
    (tmp_path / "run").mkdir()
    write_masks(m, tmp_path / "run" / "masks.parquet")
    (tmp_path / "run" / "provenance.json").write_text("{}")  # a finished run's record
    got = read_masks(tmp_path / "run")
    np.testing.assert_array_equal(got.mask_el_deg, m.mask_el_deg)
    (tmp_path / "empty").mkdir()
    with pytest.raises(MaskFileError, match=r"empty: a folder without masks\.parquet"):
        read_masks(tmp_path / "empty")


# ---------------------------------------------------------------- exporters
def test_urbannav_csv_rows_and_conservative_samples(tmp_path):
    m = make_set(step=0.5)
    path = to_urbannav_csv(m, tmp_path / "skymask.csv")
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    assert data.shape == (m.n_pos, 3 + 361)
    np.testing.assert_allclose(data[:, 0], m.lat_deg, atol=1e-9)
    np.testing.assert_allclose(data[:, 1], m.lon_deg, atol=1e-9)
    np.testing.assert_allclose(data[:, 2], m.h_m, atol=1e-3)
    eff = m.mask_el_deg.astype(float) + m.margin_deg
    for i in range(m.n_pos):
        want = np.array([brute_window_max(eff[i], 0.5, a, 1.0) for a in range(361)])
        want = np.minimum(want, 90.0)
        assert (data[i, 3:] >= want - 1e-5).all()
        assert (data[i, 3:] - want < 0.01 + 1e-9).all()
    np.testing.assert_array_equal(data[:, 3], data[:, -1])  # 0 and 360 deg agree
    # whatever lookup a reader uses, it never goes below the true effective mask
    rng = np.random.default_rng(9)
    az = rng.uniform(0, 360, 2000)
    for i in (0, 5):
        true = m.mask_at(m.chainage_m[i], az)
        row = data[i, 3:]
        assert (row[np.round(az).astype(int)] >= true - 1e-5).all()
        assert (row[np.floor(az).astype(int)] >= true - 1e-5).all()
        assert (row[np.ceil(az).astype(int)] >= true - 1e-5).all()
        assert (np.interp(az, np.arange(361.0), row) >= true - 1e-5).all()


def test_exports_never_write_negative_zero(tmp_path):
    n = 2
    m = MaskSet.from_arrays(
        [0.0, 10.0], np.full(n, 50.0), np.full(n, 4.0), 0.0, np.zeros(n), np.zeros((n, 360)),
        margin_deg=np.float32(0.0),
    )  # fmt: skip
    texts = [
        to_urbannav_csv(m, tmp_path / "u.csv").read_text(),
        to_pvgis_horizon(m, 0.0, tmp_path / "p.txt").read_text(),
        to_pvgis_horizon(m, 0.0, tmp_path / "h.txt", layout="userhorizon").read_text(),
    ]
    for text in texts:
        assert "-0.00" not in text and "0.00" in text


def test_urbannav_header_option(tmp_path):
    path = to_urbannav_csv(make_set(n_pos=3), tmp_path / "h.csv", header=True)
    first = path.read_text().splitlines()[0].split(",")
    assert first[:4] == ["lat_deg", "lon_deg", "h_m", "e_0"] and first[-1] == "e_360"
    bare = to_urbannav_csv(make_set(n_pos=3), tmp_path / "n.csv", header=False)
    assert np.loadtxt(bare, delimiter=",").shape == (3, 364)


def test_urbannav_default_keeps_every_position_for_a_reader_of_urbannavs_files(tmp_path):
    # UrbanNav's sky-mask tables start with one header line, and readers written for them
    # skip it (csv.reader + next(reader)); a header-less default lost the first position,
    # whose place then got the second position's (lower) mask by nearest lookup.
    m = make_set(n_pos=3)
    path = to_urbannav_csv(m, tmp_path / "skymask.csv")
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        next(reader)  # the header line of UrbanNav's files
        rows = [[float(v) for v in row] for row in reader]
    assert len(rows) == m.n_pos
    np.testing.assert_allclose([r[0] for r in rows], m.lat_deg, atol=1e-9)
    np.testing.assert_allclose([r[1] for r in rows], m.lon_deg, atol=1e-9)


def read_rtklib_elmask(path):
    """readelmask of the RTKLIB forks with ``file-elmaskfile`` (MALIB / MRTKLIB rtkcmn.c),
    transcribed: fgets into char[256] (chunks of at
    most 255 bytes, so a longer line goes on as a new "line"), text after % or # ignored, a
    chunk counts when it starts with two numbers, at most 360 of them; EL_i holds for
    AZ_i <= az < AZ_{i+1}, stored as int16 tenths of a degree, truncated."""
    chunks = []
    for line in path.read_bytes().decode("ascii").splitlines(keepends=True):
        chunks += [line[k:k + 255] for k in range(0, len(line), 255)]
    az, el = [], []
    for chunk in chunks:
        if len(az) >= 360:
            break
        text = chunk.split("%")[0].split("#")[0]
        m = re.match(r"\s*([-+.\deE]+)\s+([-+.\deE]+)", text)  # sscanf("%lf %lf") == 2
        if m:
            try:
                az.append(float(m.group(1)))
                el.append(float(m.group(2)))
            except ValueError:
                continue
    elmask = np.zeros(360, int)
    j, mask = 0, 0.0
    for i in range(360):
        if j < len(az) and i >= int(az[j]):
            mask = el[j]
            j += 1
        elmask[i] = int(mask / 0.1)
    return elmask, np.array(el)


def read_rtkplot_elmask(path, variant):
    """The 361-slot readers, transcribed: RTKPLOT's ReadElMaskData (Qt app, "rtkplot") and
    simobs's readelmask (util/simobs/simobs.c, "simobs"). Slots 0..360 start at 0; a line
    ``az1 el1`` (not starting with %) with ``az0 < az1 <= 360`` and ``0 <= el1 <= 90`` sets
    slots ``int(az0) <= j < int(az1)`` to ``el0`` and then slot ``int(az1)`` to ``el1``
    (rtkplot) or slots ``int(az0) <= j <= int(az1)`` to ``el0`` (simobs); then ``az0, el0 =
    az1, el1``. Both look up ``slot[int(az + 0.5)]``."""
    slots = np.zeros(361)
    az0 = el0 = 0.0
    for line in path.read_text().splitlines():
        if line.startswith("%"):
            continue
        parts = line.split()
        if len(parts) < 2:
            continue
        az1, el1 = float(parts[0]), float(parts[1])
        if az0 < az1 <= 360.0 and 0.0 <= el1 <= 90.0:
            if variant == "rtkplot":
                slots[int(az0):int(az1)] = el0
                slots[int(az1)] = el1
            else:
                slots[int(az0):int(az1) + 1] = el0
        az0, el0 = az1, el1
    return slots


def test_rtklib_mask_is_conservative_after_rtklib_truncation(tmp_path):
    m = make_set(step=0.5)
    ch = float(m.chainage_m[4])
    path = to_rtklib_mask(m, ch + 1.0, tmp_path / "elmask.txt")
    elmask, el = read_rtklib_elmask(path)
    assert el.size == 360 and (el <= 90.0).all()
    eff = m.mask_el_deg[4].astype(float) + m.margin_deg[4]
    for a in range(360):
        # bins touching [a - 0.5, a + 1]: floor lookups need [a, a + 1], rounding [a - 0.5, a + 0.5]
        want = brute_window_max(eff, 0.5, a + 0.25, 0.75)
        assert elmask[a] * 0.1 >= want - 1e-5
        assert elmask[a] * 0.1 < want + 0.1 + 1e-9
    rng = np.random.default_rng(10)
    az = rng.uniform(0, 360, 3000)
    # RTKLIB testelmask: masked when el < elmask[floor(az)] * 0.1
    assert (elmask[np.floor(az).astype(int)] * 0.1 >= m.mask_at(ch, az) - 1e-5).all()
    assert path.read_text().startswith("% PREDISAT mask at chainage")


@pytest.mark.parametrize("variant", ["rtkplot", "simobs"])
def test_rtklib_mask_is_conservative_for_the_rounding_readers(tmp_path, variant):
    m = make_set(step=0.5)
    ch = float(m.chainage_m[4])
    mask = m.effective_mask_deg.copy()
    mask[4, -1] = 89.0  # a wall just west of north: the slot the rounding readers left at 0
    m = MaskSet.from_arrays(
        m.chainage_m, m.lat_deg, m.lon_deg, m.h_m, m.heading_deg, mask, az_step_deg=0.5,
    )  # fmt: skip
    slots = read_rtkplot_elmask(to_rtklib_mask(m, ch, tmp_path / "e.txt"), variant)
    az = np.concatenate([np.linspace(0.0, 360.0, 36000, endpoint=False), [359.6, 359.99]])
    assert (slots[(az + 0.5).astype(int)] >= m.mask_at(ch, az) - 1e-5).all()


def test_rtklib_mask_ignores_long_provenance(tmp_path):
    # A provenance longer than RTKLIB's 255-byte line buffer, whose continuation would parse as
    # an "AZ EL" pair (and push the last azimuth out of RTKLIB's 360 slots) unless wrapped.
    base = make_set(step=0.5)
    ch = float(base.chainage_m[4])
    ref, _ = read_rtklib_elmask(to_rtklib_mask(base, ch, tmp_path / "ref.txt"))
    long = MaskSet.from_arrays(
        base.chainage_m, base.lat_deg, base.lon_deg, base.h_m, base.heading_deg,
        base.mask_el_deg, az_step_deg=0.5, source=base.source, margin_deg=base.margin_deg,
        provenance={"survey": "x" * 236 + " 45 80 " + "y" * 300, "note": "10 5 " * 80},
    )  # fmt: skip
    path = to_rtklib_mask(long, ch, tmp_path / "long.txt")
    lines = path.read_text().splitlines()
    assert max(len(line) for line in lines) < 255
    logical: list[str] = []  # continuation lines "% + ..." glued back on
    for line in (ln[2:] for ln in lines if ln.startswith("% ")):
        if line.startswith("+ "):
            logical[-1] += line[2:]
        else:
            logical.append(line)
    assert "provenance: " + json.dumps(long.provenance, sort_keys=True) in logical
    elmask, el = read_rtklib_elmask(path)
    assert el.size == 360
    np.testing.assert_array_equal(elmask, ref)


def test_rtklib_values_survive_truncation_for_awkward_tenths(tmp_path):
    # 12.3 / 0.1 == 122.999... in floating point: a naive "12.3" would be stored as 12.2
    n = 2
    mask = np.full((n, 360), 12.3)
    mask[:, 100:110] = 89.99
    m = MaskSet.from_arrays(
        [0.0, 10.0],
        np.full(n, 50.0),
        np.full(n, 4.0),
        0.0,
        np.zeros(n),
        mask,
        margin_deg=np.float32(0.0),
    )
    elmask, _ = read_rtklib_elmask(to_rtklib_mask(m, 0.0, tmp_path / "e.txt"))
    assert elmask[0] == 123  # 12.3 kept, not truncated to 12.2 nor bumped to 12.4
    assert elmask[105] == 900


def test_pvgis_table_and_userhorizon(tmp_path):
    m = make_set(step=1.0)
    i = 7
    ch = float(m.chainage_m[i])
    table = to_pvgis_horizon(m, ch, tmp_path / "horizon.csv")
    lines = table.read_text().splitlines()
    assert lines[0].startswith("Latitude (decimal degrees):")
    assert float(lines[0].split("\t")[-1]) == pytest.approx(m.lat_deg[i], abs=1e-6)
    assert float(lines[1].split("\t")[-1]) == pytest.approx(m.lon_deg[i], abs=1e-6)
    assert lines[2] == "" and lines[3].split() == ["A", "H_hor"]
    rows = []
    for line in lines[4:]:
        if not line.strip():
            break
        rows.append([float(v) for v in line.split()])
    a_pvgis, h = np.array(rows).T
    np.testing.assert_allclose(a_pvgis, np.arange(-180.0, 180.1, 7.5))
    az_north = a_pvgis + 180.0  # PVGIS: 0 = south, 90 = west, -90 = east
    eff = m.mask_el_deg[i].astype(float) + m.margin_deg[i]
    want = np.minimum([brute_window_max(eff, 1.0, a % 360, 7.5) for a in az_north], 90.0)
    assert (h >= want - 1e-5).all() and (h - want < 0.01 + 1e-9).all()
    # linear interpolation of the profile never dips below the true mask
    rng = np.random.default_rng(11)
    az = rng.uniform(0, 360, 3000)
    assert (np.interp(az, az_north, h) >= m.mask_at(ch, az) - 1e-5).all()

    up = np.loadtxt(to_pvgis_horizon(m, ch, tmp_path / "up.txt", layout="userhorizon"))
    np.testing.assert_array_equal(up, h[:-1])  # clockwise from north, 48 values

    up12 = np.loadtxt(
        to_pvgis_horizon(m, ch, tmp_path / "u12.txt", layout="userhorizon", n_directions=12)
    )
    want12 = [
        math.ceil(min(brute_window_max(eff, 1.0, a, 30.0), 90.0) * 100 - 1e-6) / 100
        for a in range(0, 360, 30)
    ]
    np.testing.assert_allclose(up12, want12, atol=0.0100001)


def test_exports_cap_at_90_and_reject_uncovered_chainage(tmp_path):
    n = 2
    m = MaskSet.from_arrays(
        [0.0, 10.0],
        np.full(n, 50.0),
        np.full(n, 4.0),
        0.0,
        np.zeros(n),
        np.full((n, 360), 89.0),
        margin_deg=5.0,
    )
    up = np.loadtxt(to_pvgis_horizon(m, 0.0, tmp_path / "u.txt", layout="userhorizon"))
    assert (up == 90.0).all()
    data = np.loadtxt(to_urbannav_csv(m, tmp_path / "u.csv"), delimiter=",", skiprows=1)
    assert (data[:, 3:] == 90.0).all()
    with pytest.raises(MaskError, match="outside"):
        to_rtklib_mask(m, 100.0, tmp_path / "e.txt")
    with pytest.raises(ValueError, match="layout"):
        to_pvgis_horizon(m, 0.0, tmp_path / "x.txt", layout="json")


def test_a_flipped_bit_in_a_data_page_is_refused_not_read_as_a_lower_mask(good_file, tmp_path):
    """Every data page carries a CRC-32 that the reader verifies: without it, a bit flipped by
    storage or a copy changes mask values silently (a user trial: bins lowered by up to 45 deg)."""
    data = good_file.read_bytes()
    truth = pq.read_table(good_file).column("mask_el_deg").to_pylist()
    changed = 0
    for pos in range(8, len(data) - 8, 97):  # bytes across the file, footer excluded
        flipped = bytearray(data)
        flipped[pos] ^= 0x10
        bad = tmp_path / "flip.parquet"
        bad.write_bytes(bytes(flipped))
        try:  # what a reader without the checksum would see
            silent = pq.read_table(bad).column("mask_el_deg").to_pylist()
        except (pa.ArrowException, OSError):
            silent = None
        if silent is None or silent == truth:
            continue
        changed += 1  # values changed silently for a plain reader: read_masks must refuse
        with pytest.raises(MaskFileError, match=r"flip\.parquet: damaged: a data page fails"):
            read_masks(bad)
    assert changed >= 3  # a test of the test: some flips do change the values silently
    # files written before the checksums (none in their pages) read as before
    plain = tmp_path / "plain.parquet"
    pq.write_table(pq.read_table(good_file), plain, compression="zstd")
    np.testing.assert_array_equal(read_masks(plain).mask_el_deg, read_masks(good_file).mask_el_deg)


def _open_stretch(chainage_m):
    """Positions at ``chainage_m``, 5 deg everywhere (open sky), on a short straight."""
    n = len(chainage_m)
    lon = np.linspace(4.45, 4.46, n)
    return MaskSet.from_arrays(chainage_m, np.full(n, 50.45), lon, np.full(n, 150.0),
                               np.full(n, 60.0), np.full((n, 360), 5.0))  # fmt: skip


def test_a_hole_between_positions_is_closed_on_reading_not_covered_by_its_neighbours(tmp_path):
    from predisat.masks.fileformat import MaskHoleWarning
    from predisat.masks.maskset import concat_masksets

    # two stretches joined, 1.9 km apart: open sky (5 deg) where surveyed, nothing between
    joined = concat_masksets([_open_stretch(np.arange(0.0, 101.0, 10.0)),
                              _open_stretch(np.arange(2000.0, 2101.0, 10.0))])  # fmt: skip
    path = write_masks(joined, tmp_path / "joined.parquet")
    with pytest.warns(MaskHoleWarning, match="1 hole.*100-2000 m"):
        back = read_masks(path)
    inside = (back.chainage_m > 100.0) & (back.chainage_m < 2000.0)
    # every chainage of the hole, cell edges included, rests on a position that trusts nothing
    probe = np.linspace(106.0, 1994.0, 500)
    assert np.all(back.mask_at(probe, 0.0) >= 90.0)
    assert np.all(back.worst_case(900.0, 1100.0) >= 90.0)
    assert np.all(back.source[inside] == BinSource.ASSUMED)
    # the surveyed positions keep their masks; the batch run's raw reading keeps the hole
    first = back.subset(0.0, 100.0).mask_el_deg
    assert np.array_equal(first, joined.subset(0.0, 100.0).mask_el_deg)
    assert read_masks(path, close_holes=False).n_pos == joined.n_pos
    # and the set says so: written again, its filler positions are not taken for survey
    assert back.provenance["gaps_closed_m"] == [[100.0, 2000.0]]
    assert "gaps_closed_m" not in joined.provenance  # the input untouched


def test_the_positions_closing_a_hole_lie_on_the_track_on_a_curve(tmp_path):
    from predisat.masks.fileformat import MaskHoleWarning
    from predisat.track.map import demo_track

    track = demo_track()
    # line 144 between 4.4 and 5.6 km, every 10 m, with 1 km missing; the chord across the
    # hole leaves the track by tens of metres
    ch = np.r_[np.arange(4400.0, 4501.0, 10.0), np.arange(5500.0, 5601.0, 10.0)]
    ms = MaskSet.from_track(track, ch, np.full((ch.size, 360), 5.0))
    with pytest.warns(MaskHoleWarning):
        back = read_masks(write_masks(ms, tmp_path / "m.parquet"))
    new = ~np.isin(back.chainage_m, ch)
    assert new.sum() == 2 and np.all(back.mask_el_deg[new] == 90.0)
    proj = track.project(back.lat_deg[new], back.lon_deg[new])
    assert np.all(np.abs(proj.offset_m) < 0.5)
    np.testing.assert_allclose(proj.chainage_m, back.chainage_m[new], atol=0.5)
    assert np.all(back.mask_at(np.linspace(4506.0, 5494.0, 300), 0.0) >= 90.0)


def _written(values, path):
    """A mask file of ``values`` (n, 360) at positions 10 m apart on a straight stretch."""
    n = len(values)
    m = MaskSet.from_arrays(np.arange(0.0, 10.0 * n, 10.0), np.full(n, 50.45),
                            np.linspace(4.45, 4.46, n), np.full(n, 150.0), np.full(n, 60.0),
                            values)  # fmt: skip
    return write_masks(m, path)


def test_masks_written_in_radians_are_warned_about_not_refused(tmp_path):
    """A user trial wrote radians: read silently, they trusted like no mask at all."""
    import warnings

    from predisat.masks.fileformat import MaskUnitWarning

    n = 5
    rng = np.random.default_rng(3)
    deg = rng.uniform(5.0, 60.0, (n, 360))

    def write(values, name):
        return _written(values, tmp_path / name)

    with pytest.warns(MaskUnitWarning, match=r"rad\.parquet: every mask value is at most 1\.0"):
        read_masks(write(np.radians(deg), "rad.parquet"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", MaskUnitWarning)
        read_masks(write(deg, "deg.parquet"))  # degrees: nothing said
        read_masks(write(np.zeros((n, 360)), "open.parquet"))  # an open sky: nothing said


def test_a_file_joined_from_radians_and_degrees_is_warned_about(tmp_path):
    """A trial's file joined from a tool in radians and one in degrees read silently (the
    file-wide check saw the degrees): 47 % of the bins were lowered by up to 84 deg."""
    import warnings

    from predisat.masks.fileformat import MaskUnitWarning

    n = 20
    rng = np.random.default_rng(4)
    deg = rng.uniform(5.0, 60.0, (n, 360))

    def write(values, name):
        return _written(values, tmp_path / name)

    mixed = deg.copy()
    mixed[8:] = np.radians(deg[8:])
    with pytest.warns(MaskUnitWarning, match=r"12 of 20 positions \(the first at chainage "
                                             r"80\.0 m\) hold masks of at most pi/2"):  # fmt: skip
        read_masks(write(mixed, "mixed.parquet"))
    open_ = deg.copy()
    open_[3:5] = rng.uniform(0.0, 1.5, (2, 360))  # two open positions in degrees: not a mix
    with warnings.catch_warnings():
        warnings.simplefilter("error", MaskUnitWarning)
        read_masks(write(open_, "open_two.parquet"))


def test_sparse_positions_are_warned_about(tmp_path):
    """A trial's decimated files (2, 3 or 6 positions, 40-200 m apart) read without a word:
    each position stood for up to 100 m either side and trusted up to 85 deg more."""
    import warnings

    from predisat.masks.fileformat import SPARSE_SPACING_M, MaskSpacingWarning

    def write(step_m, n, name):
        ch = np.arange(0.0, step_m * n, step_m)
        m = MaskSet.from_arrays(ch, np.full(n, 50.45), np.linspace(4.45, 4.46, n),
                                np.full(n, 150.0), np.full(n, 60.0),
                                np.full((n, 360), 20.0))  # fmt: skip
        return write_masks(m, tmp_path / name)

    with pytest.warns(MaskSpacingWarning, match=r"its 2 positions lie 200 m apart .* 100 m of "
                                                r"line either side"):  # fmt: skip
        read_masks(write(200.0, 2, "two.parquet"))
    with pytest.warns(MaskSpacingWarning, match="6 positions lie 40 m apart"):
        read_masks(write(40.0, 6, "six.parquet"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", MaskSpacingWarning)
        read_masks(write(10.0, 30, "survey.parquet"))
        read_masks(write(SPARSE_SPACING_M, 30, "edge.parquet"))


def test_a_process_folder_needs_its_run_record(tmp_path):
    """A stopped `predisat process` rerun leaves masks.parquet without provenance.json (or the
    two of different runs); such a folder is refused, the mask file itself still reads."""
    import dataclasses

    m = dataclasses.replace(make_set(), provenance={"run_key": "aaaa"})
    write_masks(m, tmp_path / "masks.parquet")
    with pytest.raises(MaskFileError, match=r"without provenance\.json.*rerun the same"):
        read_masks(tmp_path)
    assert read_masks(tmp_path / "masks.parquet").n_pos == m.n_pos
    (tmp_path / "provenance.json").write_text(json.dumps({"run_key": "bbbb"}))
    with pytest.raises(MaskFileError, match=r"run aaaa\) and provenance.json \(run bbbb\)"):
        read_masks(tmp_path)
    (tmp_path / "provenance.json").write_text(json.dumps({"run_key": "aaaa"}))
    assert read_masks(tmp_path).n_pos == m.n_pos


def test_every_way_to_a_process_folder_needs_its_run_record(tmp_path):
    """A review: `predisat export` and `evaluate` took the folder's file through
    mask_file_path, past the record check of read_masks."""
    from predisat.masks.fileformat import mask_file_path

    write_masks(make_set(), tmp_path / "masks.parquet")
    with pytest.raises(MaskFileError, match=r"without provenance\.json"):
        mask_file_path(tmp_path)
    (tmp_path / "provenance.json").write_text("{}")
    assert mask_file_path(tmp_path) == tmp_path / "masks.parquet"


def test_an_unfinished_process_folder_says_to_finish_the_run(tmp_path):
    """A user trial gave `locator run` the folder of an interrupted `predisat process` run."""
    (tmp_path / "empty").mkdir()
    with pytest.raises(MaskFileError, match=r"folder without masks\.parquet") as err:
        read_masks(tmp_path / "empty")
    assert "rerun" not in str(err.value)
    (tmp_path / "run" / "chunks").mkdir(parents=True)
    with pytest.raises(MaskFileError, match="has not finished: rerun the same `predisat process`"):
        read_masks(tmp_path / "run")


def test_a_hole_closed_on_reading_is_not_closed_again_read_twice(tmp_path):
    """A hole of 19 spacings closed on reading (two positions, one spacing inside each end)
    left a gap between those two fillers that every later read (or run_locator's close_gaps
    of a set read) took for a new hole: two more positions each pass and a hole that never was
    in provenance.gaps_closed_m ([[100, 2000], [110, 1990], [120, 1980], ...]) (m8)."""
    import warnings

    from predisat.masks.fileformat import MaskHoleWarning
    from predisat.masks.gaps import close_gaps
    from predisat.masks.maskset import concat_masksets

    joined = concat_masksets([_open_stretch(np.arange(0.0, 101.0, 10.0)),
                              _open_stretch(np.arange(2000.0, 2101.0, 10.0))])  # fmt: skip
    with pytest.warns(MaskHoleWarning):
        once = read_masks(write_masks(joined, tmp_path / "a.parquet"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", MaskHoleWarning)
        twice = read_masks(write_masks(once, tmp_path / "b.parquet"))
    assert twice.n_pos == once.n_pos
    assert twice.provenance["gaps_closed_m"] == [[100.0, 2000.0]]
    again, holes = close_gaps(once)  # run_locator closes a set given in memory again
    assert holes == [] and again.n_pos == once.n_pos
    # a real hole elsewhere is still closed and recorded
    more = concat_masksets([twice, _open_stretch(np.arange(3000.0, 3101.0, 10.0))])
    closed, holes = close_gaps(more)
    assert holes == [(2100.0, 3000.0)]
    assert closed.provenance["gaps_closed_m"][-1] == [2100.0, 3000.0]
