"""Tests of the flight-data I/O layer (fuelhm_bench.io.flights / .tables)."""

from __future__ import annotations

import gzip

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from fuelhm_bench.errors import DataFormatError, OutputPathError, ParameterError
from fuelhm_bench.io import (
    SUPPORTED_SUFFIXES,
    FlightArrays,
    FlightRejection,
    FlightWriter,
    check_flight,
    iter_flights,
    labels_path_for,
    read_flights,
    read_labels,
    split_flights,
    validate_flight_table,
    write_flights,
    write_labels,
)

FORMATS = ["parquet", "csv", "csv.gz"]


def make_table(flight_ids=(1, 2, 3), n=5, interleave=False) -> pd.DataFrame:
    """A small valid flight table with every optional column and one unknown column."""
    frames = []
    for k, fid in enumerate(flight_ids):
        t = np.arange(n) * 0.1
        frames.append(
            pd.DataFrame(
                {
                    "flight_id": [fid] * n,
                    "unit_id": [f"SN{k % 2}"] * n,
                    "time_s": t,
                    "current_mA": np.sin(t + k) * 3.0 + 0.1234567890123,
                    "position_mm": 20.0 + np.cos(t) / 3.0,
                    "demand_mm": np.full(n, 20.5),
                    "n2_pct": np.linspace(60.0, 95.0, n),
                    "fuel_temp_degC": np.full(n, 40.0 + k),
                    "phase": ["climb"] * (n - 2) + ["cruise"] * 2,
                    "rig_note": [f"note{k}"] * n,
                }
            )
        )
    table = pd.concat(frames, ignore_index=True)
    if interleave:
        order = np.argsort(np.tile(np.arange(n), len(flight_ids)), kind="stable")
        table = table.iloc[order].reset_index(drop=True)
    return table


def minimal(flight_id=1, time_s=(0.0, 0.1, 0.2, 0.3), current=None, position=None, **extra):
    """A one-flight table with only the required columns (plus ``extra``)."""
    n = len(time_s)
    data = {
        "flight_id": [flight_id] * n,
        "time_s": list(time_s),
        "current_mA": list(current) if current is not None else list(np.arange(n, dtype=float)),
        "position_mm": list(position) if position is not None else list(10.0 + 0.5 * np.arange(n)),
    }
    data.update(extra)
    return pd.DataFrame(data)


def only_rejection(table: pd.DataFrame, **kwargs) -> FlightRejection:
    flights, rejections = split_flights(table, source="test.csv", **kwargs)
    assert flights == []
    assert len(rejections) == 1
    return rejections[0]


def only_flight(table: pd.DataFrame, **kwargs) -> FlightArrays:
    flights, rejections = split_flights(table, source="test.csv", **kwargs)
    assert rejections == []
    assert len(flights) == 1
    return flights[0]


# ---------------------------------------------------------------------------
# Round trips
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("ids", [(1, 2, 30), ("F-001", "F-002", "007")])
def test_round_trip_every_format(tmp_path, fmt, ids):
    table = make_table(ids)
    path = write_flights(table, tmp_path / f"flights.{fmt}")
    back = read_flights(path)
    pd.testing.assert_frame_equal(back, validate_flight_table(table))
    if isinstance(ids[0], int):
        assert back["flight_id"].dtype == np.int64
    else:
        assert isinstance(back["flight_id"].dtype, pd.StringDtype)
        assert back["flight_id"].unique().tolist() == list(ids)  # "007" keeps its zeros
    assert back["current_mA"].to_numpy().tobytes() == table["current_mA"].to_numpy().tobytes()


def test_csv_integer_looking_ids(tmp_path):
    path = tmp_path / "f.csv"
    path.write_text(
        "flight_id,unit_id,time_s,current_mA,position_mm\n"
        "7,007,0,1,2\n7,007,1,2,2\n-3,12,0,1,2\n"
    )
    table = read_flights(path)
    assert table["flight_id"].dtype == np.int64
    assert table["flight_id"].tolist() == [7, 7, -3]
    assert table["unit_id"].tolist() == ["007", "007", "12"]  # "007" is not canonical


def test_read_keeps_unknown_columns_and_column_order(tmp_path):
    table = make_table()
    back = read_flights(write_flights(table, tmp_path / "f.parquet"))
    assert list(back.columns) == list(table.columns)
    assert back["rig_note"].tolist() == table["rig_note"].tolist()


def test_validate_does_not_modify_input():
    table = minimal(current=["1", "2", "3", "4"])
    copy = table.copy()
    out = validate_flight_table(table)
    pd.testing.assert_frame_equal(table, copy)
    assert out["current_mA"].dtype == np.float64


def test_validate_accepts_integral_float_ids_and_nullable_numbers():
    table = minimal(flight_id=4.0)
    table["current_mA"] = table["current_mA"].astype("Float64")
    table.loc[1, "current_mA"] = pd.NA
    out = validate_flight_table(table)
    assert out["flight_id"].dtype == np.int64
    assert np.isnan(out["current_mA"].iloc[1])


# ---------------------------------------------------------------------------
# Bad files
# ---------------------------------------------------------------------------


def test_missing_file(tmp_path):
    path = tmp_path / "nope.parquet"
    with pytest.raises(DataFormatError, match="does not exist") as info:
        read_flights(path)
    assert str(path) in str(info.value)


def test_unknown_suffix_lists_supported_formats(tmp_path):
    path = tmp_path / "flights.xlsx"
    path.write_text("x")
    with pytest.raises(DataFormatError) as info:
        read_flights(path)
    message = str(info.value)
    assert "flights.xlsx" in message
    for suffix in SUPPORTED_SUFFIXES:
        assert suffix in message


@pytest.mark.parametrize("fmt", FORMATS)
def test_empty_file(tmp_path, fmt):
    path = tmp_path / f"empty.{fmt}"
    path.write_bytes(b"")
    with pytest.raises(DataFormatError, match=r"is empty \(0 bytes\)") as info:
        read_flights(path)
    assert str(path) in str(info.value)


def test_gzip_of_nothing_is_empty(tmp_path):
    path = tmp_path / "empty.csv.gz"
    path.write_bytes(gzip.compress(b""))
    with pytest.raises(DataFormatError, match="is empty: it has no header line"):
        read_flights(path)


def test_header_only_csv_has_no_samples(tmp_path):
    path = tmp_path / "h.csv"
    path.write_text("flight_id,time_s,current_mA,position_mm\n")
    with pytest.raises(DataFormatError, match="contains no samples") as info:
        read_flights(path)
    assert str(path) in str(info.value)


def test_zero_row_parquet_has_no_samples(tmp_path):
    path = tmp_path / "z.parquet"
    minimal().iloc[:0].to_parquet(path)
    with pytest.raises(DataFormatError, match="contains no samples"):
        read_flights(path)


def test_directory_is_refused(tmp_path):
    path = tmp_path / "dir.csv"
    path.mkdir()
    with pytest.raises(DataFormatError, match="is a directory"):
        read_flights(path)


@pytest.mark.parametrize(
    ("name", "content"),
    [
        ("garbage.parquet", b"this is not parquet at all"),
        ("garbage.csv.gz", b"not gzip data"),
        ("garbage.csv", b'flight_id,time_s\n"1,2\n'),  # unterminated quote
        ("latin.csv", b"flight_id,time_s,current_mA,position_mm\n\xff\xfe,1,2,3\n"),
    ],
)
def test_unparsable_file_is_wrapped(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(DataFormatError, match="Cannot read the flight file") as info:
        read_flights(path)
    assert str(path) in str(info.value)
    assert info.value.__cause__ is not None  # the original error is chained, not shown raw


@pytest.mark.parametrize("fmt", FORMATS)
def test_missing_required_column(tmp_path, fmt):
    path = tmp_path / f"f.{fmt}"
    table = make_table().drop(columns=["position_mm"])
    if fmt == "parquet":
        table.to_parquet(path, index=False)
    else:
        table.to_csv(path, index=False)
    with pytest.raises(DataFormatError) as info:
        read_flights(path)
    message = str(info.value)
    assert str(path) in message
    assert "missing the required column(s) ['position_mm']" in message
    assert "found columns" in message and "'current_mA'" in message


def test_missing_column_hint_for_wrong_case(tmp_path):
    path = tmp_path / "f.csv"
    minimal().rename(columns={"current_mA": "current_ma"}).to_csv(path, index=False)
    with pytest.raises(DataFormatError, match="found 'current_ma' for 'current_mA'"):
        read_flights(path)


def test_bad_number_names_file_column_row_and_line(tmp_path):
    path = tmp_path / "f.csv"
    path.write_text(
        "flight_id,time_s,current_mA,position_mm\n1,0,1.0,2\n1,1,1.5,2\n1,2,oops,2\n1,3,bad,2\n"
    )
    with pytest.raises(DataFormatError) as info:
        read_flights(path)
    message = str(info.value)
    assert str(path) in message
    assert "'current_mA'" in message and "'oops'" in message
    assert "row 2" in message and "line 4" in message
    assert "2 bad value(s)" in message


def test_bad_number_in_optional_column(tmp_path):
    path = tmp_path / "f.parquet"
    minimal(n2_pct=["90", "91", "x", "93"]).to_parquet(path)
    with pytest.raises(DataFormatError, match=r"'n2_pct'.*'x' at row 2"):
        read_flights(path)


def test_empty_csv_cells_are_nan_not_errors(tmp_path):
    path = tmp_path / "f.csv"
    path.write_text("flight_id,time_s,current_mA,position_mm\n1,0,,2\n1,1,1.5,\n")
    table = read_flights(path)
    assert np.isnan(table["current_mA"].iloc[0]) and np.isnan(table["position_mm"].iloc[1])


def test_datetime_time_column_refused():
    table = minimal()
    table["time_s"] = pd.to_datetime(table["time_s"], unit="s")
    with pytest.raises(DataFormatError, match="'time_s'.*date/time values"):
        validate_flight_table(table, source="x.parquet")


def test_missing_flight_id_value(tmp_path):
    path = tmp_path / "f.csv"
    path.write_text("flight_id,time_s,current_mA,position_mm\n1,0,1,2\n,1,2,2\n")
    with pytest.raises(DataFormatError, match=r"'flight_id'.*missing at row 1.*line 3"):
        read_flights(path)


@pytest.mark.parametrize(
    ("ids", "dtype", "expected"),
    [
        ([1.0, 1.5, 2.0, 2.0], "float64", "the value 1.5 is not an integer at row 1"),
        ([1, "a", 1, 1], object, r"mixes integers and strings \('a'\) at row 1"),
        (["a", "b", 3, "c"], object, r"mixes integers and strings \(3\) at row 2"),
        ([True, False, True, True], bool, "booleans"),
        ([True, False, True, True], object, r"the value True \(bool\) at row 0"),
        ([1, 2.5, 1, 1], object, r"the value 2.5 \(float\) at row 1"),
    ],
)
def test_bad_flight_id_types(ids, dtype, expected):
    table = minimal()
    table["flight_id"] = pd.Series(ids, dtype=dtype)
    with pytest.raises(DataFormatError, match=expected) as info:
        validate_flight_table(table, source="x.parquet")
    assert "'flight_id' of 'x.parquet'" in str(info.value)


def test_repeated_column_names_refused():
    table = pd.concat([minimal(), minimal()[["time_s"]]], axis=1)
    with pytest.raises(DataFormatError, match=r"repeated column names \['time_s'\]"):
        validate_flight_table(table)


# ---------------------------------------------------------------------------
# Splitting into flights
# ---------------------------------------------------------------------------


def test_iter_flights_non_contiguous_keeps_file_order():
    table = make_table((10, 20, 30), n=4, interleave=True)
    assert table["flight_id"].tolist()[:3] == [10, 20, 30]
    flights = list(iter_flights(table, source="t"))
    assert [f.flight_id for f in flights] == [10, 20, 30]
    assert all(isinstance(f.flight_id, int) for f in flights)
    for flight in flights:
        rows = table[table["flight_id"] == flight.flight_id]
        np.testing.assert_array_equal(flight.time_s, rows["time_s"])
        np.testing.assert_array_equal(flight.current_ma, rows["current_mA"])
        np.testing.assert_array_equal(flight.position_mm, rows["position_mm"])
        np.testing.assert_array_equal(flight.extras["n2_pct"], rows["n2_pct"])
        assert flight.extras["phase"].tolist() == rows["phase"].tolist()
        assert flight.unit_id == rows["unit_id"].iloc[0]
        assert flight.time_s.dtype == np.float64
        assert set(flight.extras) == {"demand_mm", "n2_pct", "fuel_temp_degC", "phase"}


def test_iter_flights_string_ids_and_no_unit():
    table = pd.concat(
        [minimal("B-2"), minimal("A-1"), minimal("B-2", time_s=(0.4, 0.5))], ignore_index=True
    )
    flights = list(iter_flights(table))
    assert [f.flight_id for f in flights] == ["B-2", "A-1"]
    assert flights[0].n_samples == 6 and flights[0].unit_id is None
    np.testing.assert_array_equal(flights[0].time_s, [0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    assert flights[0].extras == {}


def test_iter_flights_is_raw_and_validates_eagerly():
    raw = list(iter_flights(minimal(time_s=(0.2, 0.1, np.nan, 0.3))))[0]
    assert np.isnan(raw.time_s[2]) and raw.time_s[0] == 0.2
    with pytest.raises(DataFormatError, match="'position_mm'"):
        iter_flights(minimal().drop(columns="position_mm"), source="f.csv")  # no next() needed


def test_iter_flights_several_units_raises():
    table = minimal(unit_id=["A", "A", "B", "A"])
    with pytest.raises(DataFormatError, match=r"Flight 1 of 'src'.*2 different unit_id.*'A', 'B'"):
        list(iter_flights(table, source="src"))


def test_split_flights_accepts_good_flights_unchanged():
    table = make_table(("x", "y"), interleave=True)
    flights, rejections = split_flights(table, source="f.parquet")
    assert rejections == []
    raw = list(iter_flights(table))
    for got, expected in zip(flights, raw, strict=True):
        assert got.flight_id == expected.flight_id and got.unit_id == expected.unit_id
        np.testing.assert_array_equal(got.current_ma, expected.current_ma)


def test_bad_flight_does_not_affect_others():
    good = minimal(1)
    bad = minimal(2, time_s=(0.0, 0.2, 0.1, 0.3))
    flights, rejections = split_flights(pd.concat([bad, good]), source="f.csv")
    assert [f.flight_id for f in flights] == [1]
    assert [r.flight_id for r in rejections] == [2]


def test_decreasing_time_rejected():
    rejection = only_rejection(minimal(7, time_s=(0.0, 0.2, 0.1, 0.3), unit_id=["U"] * 4))
    assert rejection.flight_id == 7 and rejection.unit_id == "U"
    assert "time_s decreases from 0.2 s to 0.1 s at sample 2" in rejection.reason
    assert str(rejection).startswith("test.csv: flight 7 (unit 'U') rejected: time_s decreases")
    assert rejection.reason.endswith("If the rows are only out of order, sort each flight's samples by time_s.")


def test_decreasing_time_by_jitter_says_so():
    """Backward steps all under half the typical step read as timestamp jitter, and the message says how to fix it."""
    time = np.arange(40) * 0.01
    time[[10, 25]] += 0.012  # 12 ms late at 10 ms: the next step goes back 2 ms, twice
    reason = only_rejection(minimal(time_s=tuple(time), current=np.sin(time), position=np.cos(time))).reason
    assert "2 decrease(s) in all" in reason
    assert reason.endswith("Every decrease is under half the typical step (0.002 s at most, against 0.01 s): timestamp "
                           "jitter; give each sample its frame time (rounded to the recording's frame period).")


def test_nan_or_infinite_time_rejected():
    reason = only_rejection(minimal(time_s=(0.0, np.nan, 0.2, 0.3))).reason
    assert "time_s is missing (NaN) at 1 sample(s), first at sample 1" in reason
    reason = only_rejection(minimal(time_s=(0.0, 0.1, 0.2, np.inf))).reason
    assert "time_s is infinite" in reason


def test_identical_repeated_timestamps_dropped():
    table = minimal(
        time_s=(0.0, 0.1, 0.1, 0.1, 0.2),
        current=(0.0, 1.0, 1.0, 1.0, 2.0),
        position=(5.0, np.nan, np.nan, np.nan, 6.0),
        phase=["a", "b", "c", "d", "e"],
    )
    flight = only_flight(table)
    np.testing.assert_array_equal(flight.time_s, [0.0, 0.1, 0.2])
    np.testing.assert_array_equal(flight.current_ma, [0.0, 1.0, 2.0])
    assert flight.extras["phase"].tolist() == ["a", "b", "e"]  # the later duplicates go


def test_conflicting_repeated_timestamps_rejected():
    table = minimal(
        time_s=(0.0, 0.1, 0.1, 0.2), current=(0.0, 1.0, 1.0, 2.0), position=(5.0, 5.1, 5.3, 5.4)
    )
    reason = only_rejection(table).reason
    assert "time_s repeats 0.1 s with different position_mm values" in reason
    assert "5.1 then 5.3 mm" in reason


def test_single_sample_and_min_samples():
    assert only_rejection(minimal(time_s=(0.0,))).reason == (
        "Only 1 sample (at least 2 are required)."
    )
    reason = only_rejection(minimal(), min_samples=5).reason
    assert reason == "Only 4 samples (at least 5 are required)."
    table = minimal(time_s=(0.0, 0.0, 0.0), current=(1.0, 1.0, 1.0), position=(2.0, 2.0, 2.0))
    reason = only_rejection(table).reason
    assert "Only 1 sample after dropping 2 repeated timestamp(s)" in reason


def test_short_nan_gap_interpolated_linearly_in_time():
    time = (0.0, 0.1, 0.2, 0.3, 0.7, 1.0)  # non-uniform: interpolation follows time, not index
    current = (0.0, 1.0, np.nan, np.nan, np.nan, 10.0)
    flight = only_flight(minimal(time_s=time, current=current), max_nan_gap=3)
    np.testing.assert_allclose(flight.current_ma, [0.0, 1.0, 2.0, 3.0, 7.0, 10.0])


def test_nan_at_edges_filled_with_nearest_value():
    flight = only_flight(minimal(current=(np.nan, 1.0, 2.0, np.nan)))
    np.testing.assert_array_equal(flight.current_ma, [1.0, 1.0, 2.0, 2.0])


def test_long_nan_run_rejected_with_length_and_place():
    time = tuple(np.round(np.arange(10) * 0.5, 3))
    position = [1.0, 2.0, np.nan, np.nan, np.nan, np.nan, 3.0, 4.0, 5.0, 6.0]
    reason = only_rejection(minimal(time_s=time, position=position)).reason
    assert "position_mm is missing (NaN) for 4 consecutive samples" in reason
    assert "from t = 1 s to t = 2.5 s" in reason
    assert "at most 3 consecutive missing samples" in reason
    flight = only_flight(minimal(time_s=time, position=position), max_nan_gap=4)
    assert np.isfinite(flight.position_mm).all()
    reason = only_rejection(minimal(current=(0.0, np.nan, 1.0, 2.0)), max_nan_gap=0).reason
    assert "current_mA is missing (NaN) for 1 consecutive samples" in reason


def test_all_nan_and_infinite_signals_rejected():
    reason = only_rejection(minimal(current=[np.nan] * 4)).reason
    assert reason == "current_mA is missing (NaN) in all 4 samples."
    reason = only_rejection(minimal(position=(1.0, -np.inf, 1.0, 1.0))).reason
    assert "position_mm is infinite at 1 sample(s), first at t = 0.1 s" in reason


def test_optional_numeric_gaps_filled_when_short_else_left_nan():
    n2 = [50.0, np.nan, 52.0, np.nan, np.nan, np.nan, np.nan, 57.0]
    time = tuple(np.arange(8) * 1.0)
    flight = only_flight(minimal(time_s=time, n2_pct=n2), max_nan_gap=3)
    np.testing.assert_array_equal(flight.extras["n2_pct"][:3], [50.0, 51.0, 52.0])
    assert np.isnan(flight.extras["n2_pct"][3:7]).all()


def test_constant_position_rejected_as_a_stuck_sensor():
    """P9: an exactly constant position while the current varies is a stuck or disconnected sensor."""
    reason = only_rejection(minimal(position=[30.0] * 4)).reason
    assert reason.startswith("position_mm is constant (30 mm) over all 4 samples while the current varies: "
                             "a stuck or disconnected position sensor")
    assert only_flight(minimal(position=(30.0, 30.0, 30.015, 30.0))).n_samples == 4  # one quantum step is a reading
    # P8 comes first: nothing varies at all is reported as the missing excitation
    assert only_rejection(minimal(current=[1.0] * 4, position=[30.0] * 4)).reason.startswith("current_mA is constant")


def test_constant_current_rejected():
    reason = only_rejection(minimal(current=[2.5] * 4)).reason
    assert reason.startswith("current_mA is constant (2.5 mA) over all 4 samples: no excitation")
    table = minimal(current=(1.0, 1.01, 1.0, 1.02))
    assert only_flight(table).n_samples == 4
    reason = only_rejection(table, min_current_range_ma=0.05).reason
    assert "current_mA spans only 0.02 mA" in reason and "more than 0.05 mA" in reason


def test_several_units_rejected_by_split():
    rejection = only_rejection(minimal(unit_id=["A", None, "B", "A"]))
    assert rejection.unit_id is None
    assert "2 different unit_id values ('A', 'B')" in rejection.reason
    flight = only_flight(minimal(unit_id=[None, "A", None, "A"]))
    assert flight.unit_id == "A"


def test_integer_unit_ids_with_missing_cells(tmp_path):
    path = tmp_path / "f.csv"
    path.write_text(
        "flight_id,unit_id,time_s,current_mA,position_mm,5\n"
        "1,7,0,1,2,x\n1,,1,2,3,y\n2,8,0,1,2,z\n2,9,1,3,3,w\n"
    )
    table = read_flights(path)
    assert table["unit_id"].dtype == "Int64"
    assert list(table.columns)[-1] == "5"  # odd names survive, as strings
    flights, rejections = split_flights(table, source=str(path))
    assert flights[0].unit_id == 7 and type(flights[0].unit_id) is int
    assert "2 different unit_id values (8, 9)" in rejections[0].reason
    assert "make flight_id unique in the file (e.g. '<unit>-<flight>')" in rejections[0].reason
    write_flights(table, tmp_path / "g.parquet")
    assert read_flights(tmp_path / "g.parquet")["unit_id"].tolist()[:2] == [7, pd.NA]


def test_split_parameters_validated():
    with pytest.raises(ParameterError, match="'min_samples' parameter must be an integer >= 2"):
        split_flights(minimal(), min_samples=1)
    with pytest.raises(ParameterError, match="'max_nan_gap'"):
        split_flights(minimal(), max_nan_gap=-1)
    with pytest.raises(ParameterError, match="'min_current_range_ma'"):
        split_flights(minimal(), min_current_range_ma=float("nan"))
    with pytest.raises(ParameterError, match="'min_current_range_ma'.*Got '1' instead"):
        check_flight(next(iter_flights(minimal())), min_current_range_ma="1")


def test_check_flight_matches_split_flights():
    table = pd.concat(
        [minimal(1, current=(0.0, np.nan, 2.0, 3.0)), minimal(2, current=[1.0] * 4)]
    )
    flights, rejections = split_flights(table, source="s")
    results = [check_flight(f, source="s") for f in iter_flights(table)]
    np.testing.assert_array_equal(results[0].current_ma, flights[0].current_ma)
    assert results[1] == rejections[0]


def test_flight_arrays_are_read_only_and_do_not_freeze_caller_arrays():
    time = np.array([0.0, 1.0])
    flight = FlightArrays(1, None, time, [1, 2], [3, 4], extras={"phase": ["a", "b"]})
    assert time.flags.writeable
    assert flight.current_ma.dtype == np.float64
    with pytest.raises(ValueError):
        flight.time_s[0] = 5.0
    with pytest.raises(AttributeError):
        flight.flight_id = 2  # type: ignore[misc]
    with pytest.raises(DataFormatError, match="flight 3.*one length"):
        FlightArrays(3, None, [0.0, 1.0], [1.0], [1.0, 2.0])


def test_split_does_not_modify_input():
    table = minimal(current=(0.0, np.nan, 2.0, 3.0))
    copy = table.copy()
    split_flights(table)
    pd.testing.assert_frame_equal(table, copy)


# ---------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", FORMATS)
def test_overwrite_protection(tmp_path, fmt):
    path = tmp_path / f"f.{fmt}"
    write_flights(minimal(), path)
    before = path.read_bytes()
    with pytest.raises(OutputPathError) as info:
        write_flights(minimal(2), path)
    message = str(info.value)
    assert str(path) in message and "overwrite=True" in message and "--force" in message
    assert path.read_bytes() == before
    write_flights(minimal(2), path, overwrite=True)
    assert read_flights(path)["flight_id"].unique().tolist() == [2]
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"f.{fmt}"]  # no temp file left


def test_write_creates_parent_directories(tmp_path):
    path = tmp_path / "a" / "b" / "f.parquet"
    assert write_flights(minimal(), path) == path
    assert path.exists()


def test_unwritable_directory(tmp_path):
    blocker = tmp_path / "not_a_dir"
    blocker.write_text("I am a file")
    path = blocker / "f.parquet"
    with pytest.raises(OutputPathError) as info:
        write_flights(minimal(), path)
    assert str(path) in str(info.value)
    assert "cannot create its directory" in str(info.value)


def test_write_to_directory_named_like_a_file(tmp_path):
    path = tmp_path / "f.csv"
    path.mkdir()
    with pytest.raises(OutputPathError, match="is a directory"):
        write_flights(minimal(), path, overwrite=True)


def test_write_rejects_invalid_table_and_creates_nothing(tmp_path):
    path = tmp_path / "f.parquet"
    with pytest.raises(DataFormatError, match="'current_mA'"):
        write_flights(minimal().drop(columns="current_mA"), path)
    with pytest.raises(DataFormatError, match="No rows were written"):
        write_flights(minimal().iloc[:0], path)
    assert list(tmp_path.iterdir()) == []


def test_write_requires_a_dataframe(tmp_path):
    with pytest.raises(DataFormatError, match="must be a pandas DataFrame. Got dict instead"):
        write_flights({"flight_id": [1]}, tmp_path / "f.csv")
    with pytest.raises(DataFormatError, match="must be a pandas DataFrame. Got list instead"):
        write_labels([1, 2], tmp_path / "l.csv")
    assert list(tmp_path.iterdir()) == []


def test_write_unknown_suffix(tmp_path):
    with pytest.raises(DataFormatError, match="suffix must be one of"):
        write_flights(minimal(), tmp_path / "f.txt")


# ---------------------------------------------------------------------------
# Labels
# ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("flights.parquet", "flights.labels.parquet"),
        ("x.csv", "x.labels.csv"),
        ("run.v2.csv.gz", "run.v2.labels.csv.gz"),
        ("UP.PARQUET", "UP.labels.PARQUET"),
    ],
)
def test_labels_path_for(tmp_path, name, expected):
    assert labels_path_for(tmp_path / name) == tmp_path / expected


def test_labels_path_for_unknown_suffix():
    with pytest.raises(DataFormatError, match="flights.json"):
        labels_path_for("flights.json")


def make_labels(ids=(1, 2, 3)) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "flight_id": list(ids),
            "unit_id": ["SN0", "SN1", "SN0"][: len(ids)],
            "mode": ["healthy", "spool_friction", "backlash"][: len(ids)],
            "intensity": [0.0, 0.25, 0.5][: len(ids)],
            "onset_flight": [-1, 2, 3][: len(ids)],
        }
    )


@pytest.mark.parametrize("fmt", FORMATS)
def test_labels_round_trip(tmp_path, fmt):
    labels = make_labels()
    path = write_labels(labels, labels_path_for(tmp_path / f"flights.{fmt}"))
    assert path.name == f"flights.labels.{fmt}"
    back = read_labels(path)
    pd.testing.assert_frame_equal(back, labels)
    assert back["flight_id"].dtype == np.int64


def test_labels_must_be_keyed_by_unique_flight_id(tmp_path):
    with pytest.raises(DataFormatError, match=r"2 rows for flight_id 2 \(row 1.*row 2"):
        write_labels(make_labels((1, 2, 2)), tmp_path / "l.parquet")
    with pytest.raises(DataFormatError, match="missing the required column 'flight_id'"):
        write_labels(make_labels().drop(columns="flight_id"), tmp_path / "l.parquet")
    path = tmp_path / "bad.labels.csv"
    path.write_text("flight_id,mode\n1,a\n1,b\n")
    with pytest.raises(DataFormatError, match=r"bad.labels.csv.*line 2.*line 3"):
        read_labels(path)
    with pytest.raises(DataFormatError, match="does not exist"):
        read_labels(tmp_path / "nope.labels.csv")


def test_labels_overwrite_protection(tmp_path):
    path = tmp_path / "l.csv"
    write_labels(make_labels(), path)
    with pytest.raises(OutputPathError, match="already exists"):
        write_labels(make_labels(), path)


# ---------------------------------------------------------------------------
# Streaming writer
# ---------------------------------------------------------------------------


def chunks_of(table: pd.DataFrame, size: int) -> list[pd.DataFrame]:
    return [table.iloc[i : i + size] for i in range(0, len(table), size)]


@pytest.mark.parametrize("fmt", FORMATS)
def test_flight_writer_chunks_equal_concatenation(tmp_path, fmt):
    table = make_table(("a", "b", "c", "d"), n=6, interleave=True)  # flights span chunks
    labels = make_labels(("a", "b", "c")).assign(mode=["m0", "m1", "m2"])
    path = tmp_path / "out" / f"flights.{fmt}"
    with FlightWriter(path) as writer:
        for chunk in chunks_of(table, 7):
            writer.write(chunk)
        writer.write_labels(labels.iloc[:2])
        writer.write_labels(labels.iloc[2:])
        writer.write(table.iloc[:0])  # empty chunks are skipped
        assert writer.n_rows == len(table)
        assert not path.exists()  # nothing published before the end of the block
    pd.testing.assert_frame_equal(read_flights(path), validate_flight_table(table))
    pd.testing.assert_frame_equal(read_labels(writer.labels_path), labels)
    assert sorted(p.name for p in path.parent.iterdir()) == sorted(
        [path.name, writer.labels_path.name]
    )
    if fmt == "parquet":
        assert pq.ParquetFile(path).num_row_groups == len(chunks_of(table, 7))
    else:
        opener = gzip.open if fmt == "csv.gz" else open
        with opener(path, "rt") as handle:
            assert sum(line.startswith("flight_id,") for line in handle) == 1


@pytest.mark.parametrize("fmt", FORMATS)
def test_failed_flight_writer_leaves_no_file(tmp_path, fmt):
    path = tmp_path / f"flights.{fmt}"
    with pytest.raises(RuntimeError, match="simulation blew up"):
        with FlightWriter(path) as writer:
            writer.write(make_table())
            writer.write_labels(make_labels())
            raise RuntimeError("simulation blew up")
    assert list(tmp_path.iterdir()) == []


def test_failed_overwrite_keeps_previous_file(tmp_path):
    path = tmp_path / "flights.parquet"
    write_flights(minimal(1), path)
    before = path.read_bytes()
    with pytest.raises(KeyboardInterrupt):
        with FlightWriter(path, overwrite=True) as writer:
            writer.write(minimal(2))
            raise KeyboardInterrupt
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["flights.parquet"]


def test_flight_writer_overwrite_protection_is_checked_first(tmp_path):
    path = tmp_path / "flights.csv"
    write_flights(minimal(), path)
    with pytest.raises(OutputPathError, match="overwrite=True") as info:
        FlightWriter(path)
    assert str(path) in str(info.value)
    labels_only = tmp_path / "other.csv"
    write_labels(make_labels(), labels_path_for(labels_only))
    with pytest.raises(OutputPathError, match=r"labels file .*other.labels.csv.*already exists"):
        FlightWriter(labels_only)
    with FlightWriter(path, overwrite=True) as writer:
        writer.write(minimal(9))
    assert read_flights(path)["flight_id"].unique().tolist() == [9]


def test_flight_writer_chunk_errors(tmp_path):
    path = tmp_path / "f.parquet"
    with pytest.raises(DataFormatError, match=r"chunk 2 .*missing the required column"):
        with FlightWriter(path) as writer:
            writer.write(minimal(1))
            writer.write(minimal(2).drop(columns="position_mm").assign(position_x=1.0))
    with pytest.raises(DataFormatError, match=r"Missing \['rig'\], unexpected \['rig_2'\]"):
        with FlightWriter(path) as writer:
            writer.write(minimal(1, rig=["a"] * 4))
            writer.write(minimal(2, rig_2=["a"] * 4))
    with pytest.raises(DataFormatError, match=r"chunk 2 .*flight_id holds strings"):
        with FlightWriter(path) as writer:
            writer.write(minimal(1))
            writer.write(minimal("two"))
    with pytest.raises(DataFormatError, match="flight_id 2 already has a label row"):
        with FlightWriter(path) as writer:
            writer.write(minimal(1))
            writer.write_labels(make_labels((1, 2)))
            writer.write_labels(make_labels((2,)))
    with pytest.raises(DataFormatError, match=r"'current_mA' of '<chunk 1 .*'x' at row 1"):
        with FlightWriter(path) as writer:
            writer.write(minimal(current=["1", "x", "2", "3"]))
    assert list(tmp_path.iterdir()) == []


def test_flight_writer_chunk_columns_may_be_reordered(tmp_path):
    path = tmp_path / "f.csv"
    first, second = minimal(1), minimal(2)
    with FlightWriter(path) as writer:
        writer.write(first)
        writer.write(second[list(reversed(second.columns))])
    expected = validate_flight_table(pd.concat([first, second], ignore_index=True))
    pd.testing.assert_frame_equal(read_flights(path), expected)


def test_flight_writer_without_rows_creates_nothing(tmp_path):
    path = tmp_path / "f.parquet"
    with pytest.raises(DataFormatError, match="No rows were written"):
        with FlightWriter(path):
            pass
    assert list(tmp_path.iterdir()) == []


def test_flight_writer_closed(tmp_path):
    writer = FlightWriter(tmp_path / "f.csv")
    writer.write(minimal())
    assert writer.close() == tmp_path / "f.csv"
    with pytest.raises(OutputPathError, match="already closed"):
        writer.write(minimal())
    with FlightWriter(tmp_path / "h.csv") as explicit:
        explicit.write(minimal())
        explicit.close()  # closing inside the block is fine; the block end does nothing more
    assert (tmp_path / "h.csv").exists()
    (tmp_path / "h.csv").unlink()
    aborted = FlightWriter(tmp_path / "g.csv")
    aborted.write(minimal())
    aborted.abort()
    aborted.abort()  # idempotent
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.csv"]


def test_flight_writer_unwritable_directory(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(OutputPathError, match="cannot create its directory") as info:
        FlightWriter(blocker / "sub" / "f.parquet")
    assert "f.parquet" in str(info.value)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_repeated_column_name_is_refused_naming_it(tmp_path, suffix):
    """Before: the CSV was read with pandas' silent 'time_s.1' rename, the Parquet file failed with a
    multi-line Arrow schema dump."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from fuelhm_bench.errors import DataFormatError
    from fuelhm_bench.io.tables import read_table

    path = tmp_path / f"dup{suffix}"
    if suffix == ".csv":
        path.write_text("flight_id,time_s,current_mA,position_mm,time_s\n0,0.0,1.0,2.0,0.0\n")
    else:
        pq.write_table(pa.Table.from_arrays([pa.array([0]), pa.array([0.0]), pa.array([1.0]), pa.array([2.0]),
                                             pa.array([0.0])],
                                            names=["flight_id", "time_s", "current_mA", "position_mm", "time_s"]),
                       path)
    with pytest.raises(DataFormatError, match=r"^'.*dup\.\w+': column names must be unique. Got 'time_s' more "
                                              r"than once\.$"):
        read_table(path)
