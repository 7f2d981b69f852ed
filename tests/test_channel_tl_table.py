"""Site-specific transmission loss: the compiled bilinear interpolation against hand values on a
tiny synthetic table, the table file's checks, the sound-speed profile file, and BELLHOP through
pelagic when it is installed."""

import importlib.util
import sys

import numpy as np
import pytest
from conftest import ROOT

from iout_mj.scenarios import load_config
from iout_mj.world.tl_table import (
    TL_CAP_DB,
    TLTable,
    TLTableError,
    compute_table,
    load_table,
    read_profile,
    save_table,
)


def tiny() -> TLTable:
    """Two depths (10, 20 m) x three ranges (100, 200, 400 m) at 50 kHz, and 70 kHz + 3 dB."""
    tl = np.array([[40.0, 50.0, 60.0], [44.0, 54.0, 70.0]])
    return TLTable([50.0, 70.0], [10.0, 20.0], [100.0, 200.0, 400.0], np.stack([tl, tl + 3]), 99.5)


@pytest.mark.parametrize(
    ("range_m", "depth_m", "tl_db"),
    [
        (100.0, 10.0, 40.0),  # a node of the grid
        (150.0, 10.0, 45.0),  # halfway along range
        (100.0, 15.0, 42.0),  # halfway along depth
        (150.0, 15.0, 47.0),  # the cell's centre: (40 + 50 + 44 + 54) / 4
        (300.0, 20.0, 62.0),  # halfway on the wider range cell: 54 + (70 - 54) / 2
        (250.0, 12.5, 0.75 * (0.75 * 50 + 0.25 * 60) + 0.25 * (0.75 * 54 + 0.25 * 70)),
        (50.0, 5.0, 40.0),  # clamped below both axes
        (1000.0, 30.0, 70.0),  # clamped above both axes
    ],
)
def test_bilinear_interpolation_by_hand(range_m, depth_m, tl_db):
    table = tiny()
    assert table.interpolate_db(50.0, range_m, depth_m)[()] == pytest.approx(tl_db, abs=1e-12)
    assert table.interpolate_db(70.0, range_m, depth_m)[()] == pytest.approx(tl_db + 3, abs=1e-12)


def test_interpolation_broadcasts_and_a_one_node_axis_is_constant():
    out = tiny().interpolate_db(50.0, [[100.0, 200.0]], [[10.0], [20.0]])
    np.testing.assert_allclose(out, [[40.0, 50.0], [44.0, 54.0]])
    one = TLTable([50.0], [30.0], [10.0, 20.0], [[[60.0, 80.0]]], 99.5)
    np.testing.assert_allclose(one.interpolate_db(50.0, [15.0, 15.0], [0.0, 90.0]), [70.0, 70.0])
    with pytest.raises(TLTableError, match=r"no TL at 60 kHz .* accepted one of \[50.0, 70.0\]"):
        tiny().interpolate_db(60.0, 100.0, 10.0)


def test_a_table_file_round_trips_as_plain_arrays(tmp_path):
    path = tmp_path / "site.npz"
    save_table(tiny(), path)
    back = load_table(path)
    np.testing.assert_array_equal(back.tl_db, tiny().tl_db)
    np.testing.assert_array_equal(back.range_m, [100.0, 200.0, 400.0])
    assert back.source_depth_m == 99.5
    with np.load(path, allow_pickle=False) as data:  # no object arrays: readable unpickled
        assert all(data[name].dtype == float for name in data.files)


def bad(**changes):
    base = {
        "frequency_khz": [50.0],
        "depth_m": [10.0, 20.0],
        "range_m": [100.0, 200.0, 400.0],
        "tl_db": np.full((1, 2, 3), 50.0),
        "source_depth_m": 99.5,
    }
    return {**base, **changes}


@pytest.mark.parametrize(
    ("arrays", "message"),
    [
        (bad(tl_db=np.full((1, 3, 2), 50.0)), r"shape \(1, 3, 2\): accepted .* = \(1, 2, 3\)"),
        (bad(tl_db=np.full((2, 3), 50.0)), r"accepted \(frequencies, depths, ranges\)"),
        (bad(range_m=[100.0, 400.0, 200.0]), "range_m is .*: accepted strictly increasing"),
        (bad(depth_m=[20.0, 20.0]), "depth_m is .*: accepted strictly increasing"),
        (bad(range_m=[-1.0, 200.0, 400.0]), "range_m holds .*: accepted finite values >= 0"),
        (bad(depth_m=[[10.0, 20.0]]), r"depth_m has shape \(1, 2\): accepted a 1-D axis"),
        (bad(source_depth_m=float("nan")), "source_depth_m is nan: accepted a finite depth"),
    ],
)
def test_bad_tables_say_what_is_accepted(arrays, message):
    with pytest.raises(TLTableError, match=message):
        TLTable(**arrays)


def test_non_finite_tl_is_named_where_it_is():
    tl = np.full((1, 2, 3), 50.0)
    tl[0, 1, 2], tl[0, 0, 0] = np.nan, np.inf
    with pytest.raises(TLTableError, match=r"tl_db is inf at 50 kHz, depth 10 m, range 100 m \(2"):
        TLTable(**bad(tl_db=tl))


def test_bad_table_files_name_the_file(tmp_path):
    extra = tmp_path / "extra.npz"
    np.savez(extra, **bad(), note=np.array([1.0]))
    with pytest.raises(TLTableError, match=r"extra.npz holds the arrays .* accepted exactly"):
        load_table(extra)
    nan = tmp_path / "nan.npz"
    np.savez(nan, **bad(range_m=[100.0, np.nan, 400.0]))
    with pytest.raises(TLTableError, match=r"nan\.npz: range_m holds"):
        load_table(nan)
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, **bad(tl_db=np.array([{"a": 1}], dtype=object)))
    with pytest.raises(TLTableError, match=r"pickled\.npz: not a readable \.npz"):
        load_table(pickled)
    with pytest.raises(TLTableError, match=r"missing\.npz: not a readable"):
        load_table(tmp_path / "missing.npz")


def test_a_profile_csv_with_a_header_and_its_refusals(tmp_path):
    good = tmp_path / "ssp.csv"
    good.write_text("depth_m, c_mps\n0, 1500\n50, 1495.5\n120, 1494\n")
    depth, speed = read_profile(good)
    np.testing.assert_array_equal(depth, [0.0, 50.0, 120.0])
    np.testing.assert_array_equal(speed, [1500.0, 1495.5, 1494.0])
    for text, message in (
        ("0, 1500\n", "at least two rows"),
        ("0, 1500\n50, 1495, 3\n", "at least two rows of 'depth_m, c_mps'"),
        ("0, 1500\n0, 1495\n", "strictly increasing"),
        ("0, 1500\n50, 340\n", r"accepted 1400 to 1650 m/s"),
    ):
        good.write_text(text)
        with pytest.raises(TLTableError, match=message):
            read_profile(good)


def test_without_pelagic_the_table_command_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pelagic", None)  # import pelagic raises ImportError
    channel = load_config(ROOT / "training/configs/env/realistic-channel.yaml").channel
    with pytest.raises(TLTableError, match=r"pip install -e \.\[bellhop\]"):
        compute_table(channel, [50.0])


@pytest.mark.skipif(
    importlib.util.find_spec("pelagic") is None,
    reason="pelagic (BELLHOP) is an optional extra: pip install -e .[bellhop]",
)
def test_bellhop_through_pelagic_gives_a_shelf_table(tmp_path):
    """The shipped realistic channel's shelf (nodes on a 100 m sand seabed, Mackenzie water at
    10 C, 35 ppt): at the AUVs' 50 m, TL grows with range and lies between practical spreading
    (15 log10 d) and spherical spreading (20 log10 d) plus Thorp absorption, at both tones."""
    from iout_mj.world.acoustics import thorp_absorption_db_per_km

    channel = load_config(ROOT / "training/configs/env/realistic-channel.yaml").channel
    table = compute_table(channel, [70.0, 50.0], max_range_m=600.0, range_step_m=50.0)
    assert table.frequency_khz.tolist() == [50.0, 70.0]
    assert table.source_depth_m == 99.5 and table.depth_m[-1] == 99.5
    assert table.tl_db.shape == (2, 21, 12) and np.all(table.tl_db < TL_CAP_DB)
    ranges = np.array([100.0, 300.0, 500.0])
    slant = np.hypot(ranges, 49.5)
    for f in (50.0, 70.0):
        tl = table.interpolate_db(f, ranges, 50.0)
        assert np.all(np.diff(tl) > 0)
        alpha = float(thorp_absorption_db_per_km(f)) * slant / 1e3
        assert np.all(tl > 15 * np.log10(slant) + alpha)
        assert np.all(tl < 20 * np.log10(slant) + alpha)
    save_table(table, tmp_path / "shelf.npz")
    np.testing.assert_array_equal(load_table(tmp_path / "shelf.npz").tl_db, table.tl_db)
