"""The indicator table: one row per flight, a fixed column contract."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.errors import DataFormatError
from fuelhm_bench.indicators import extract_indicators, extract_table, table_columns
from fuelhm_bench.testing.indicators import synthetic_flight
from fuelhm_bench.taxonomy import INDICATOR_NAMES

EXPECTED_COLUMNS = (
    ["flight_id", "unit_id", "X1", "Y1", "X2", "Y2", "Inb", "I0", "Hys0", "G_in", "G_out",
     "G_null"]
    + [f"{n}_valid" for n in ("X1", "Y1", "X2", "Y2", "Inb", "I0", "Hys0", "G_in", "G_out",
                              "G_null")]
    + ["V_in1", "V_out1", "V_in3", "V_out3", "V_in7", "V_out7", "Vsd_null", "Idle_frac",
       "Hys_lo", "Hys_hi", "I0_slope"]
    + [f"{n}_valid" for n in ("V_in1", "V_out1", "V_in3", "V_out3", "V_in7", "V_out7", "Vsd_null",
                              "Idle_frac", "Hys_lo", "Hys_hi", "I0_slope")]
    + ["n_points", "quality_reason"]
)


@dataclass
class Flight:  # the attributes of fuelhm_bench.io.flights.FlightArrays
    flight_id: object
    unit_id: object
    time_s: np.ndarray
    current_ma: np.ndarray
    position_mm: np.ndarray


@dataclass
class FlightNoUnit:
    flight_id: object
    time_s: np.ndarray
    current_ma: np.ndarray
    position_mm: np.ndarray


@pytest.fixture(scope="module")
def flights():
    full = synthetic_flight(n_excursions=200, seed=41, flight_id=101, unit_id="ESN-7")
    partial = synthetic_flight(n_excursions=200, seed=42, peak_range_ma=(-9.8, 2.0),
                               flight_id=102, unit_id="ESN-7")
    return [full, partial]


def test_columns_and_dtypes(flights):
    table = extract_table(flights)
    assert list(table.columns) == EXPECTED_COLUMNS == table_columns()
    assert len(table) == 2
    assert table["flight_id"].tolist() == [101, 102]
    assert table["unit_id"].tolist() == ["ESN-7", "ESN-7"]
    for name in INDICATOR_NAMES:
        assert table[name].dtype == np.float64
        assert table[f"{name}_valid"].dtype == bool
    assert table["n_points"].dtype == np.int64
    assert table["quality_reason"].map(type).eq(str).all()


def test_rows_match_single_flight_extraction(flights):
    table = extract_table(flights)
    for row, f in zip(table.itertuples(index=False), flights):
        r = extract_indicators(f.time_s, f.current_ma, f.position_mm)
        expected = r.to_row()
        got = row._asdict()
        for name in INDICATOR_NAMES:
            assert got[f"{name}_valid"] == expected[f"{name}_valid"]
            np.testing.assert_equal(got[name], expected[name])  # NaN == NaN
        assert got["n_points"] == r.n_points
        assert got["quality_reason"] == r.quality_reason
    full, partial = table.iloc[0], table.iloc[1]
    assert full["quality_reason"] == "" and full[[f"{n}_valid" for n in INDICATOR_NAMES]].all()
    assert np.isnan(partial["X2"]) and not partial["X2_valid"] and partial["X1_valid"]
    assert "G_out" in partial["quality_reason"]


def test_unit_id_column_only_when_present(flights):
    plain = [FlightNoUnit(f.flight_id, f.time_s, f.current_ma, f.position_mm) for f in flights]
    table = extract_table(plain)
    assert "unit_id" not in table.columns
    assert list(table.columns) == table_columns(with_unit_id=False)
    none_units = [Flight(f.flight_id, None, f.time_s, f.current_ma, f.position_mm)
                  for f in flights]
    assert "unit_id" not in extract_table(none_units).columns


def test_empty_iterable_gives_empty_table_with_the_columns():
    table = extract_table(iter([]))
    assert len(table) == 0
    assert list(table.columns) == table_columns(with_unit_id=False)


def test_bad_flight_is_named_or_flagged(flights):
    good = flights[0]
    bad = Flight("bad-17", "ESN-7", good.time_s[::-1].copy(), good.current_ma, good.position_mm)
    with pytest.raises(DataFormatError, match="flight 'bad-17'.*strictly increasing"):
        extract_table([good, bad])
    table = extract_table([good, bad], on_error="flag")
    assert len(table) == 2
    row = table.iloc[1]
    assert not row[[f"{n}_valid" for n in INDICATOR_NAMES]].any()
    assert row[list(INDICATOR_NAMES)].isna().all()
    assert "flight 'bad-17'" in row["quality_reason"]
    assert row["n_points"] == 0


def test_object_without_required_attributes():
    with pytest.raises(DataFormatError, match=r"flight #0: object of type dict has no "
                                              r"attribute\(s\) flight_id, time_s"):
        extract_table([{"time_s": [0.0]}])


def test_engines_give_the_same_table(flights):
    a = extract_table(flights, engine="numba")
    b = extract_table(flights, engine="numpy")
    pd.testing.assert_frame_equal(a, b, rtol=1e-12)


def test_accepts_io_flight_arrays(flights):
    # The reader's FlightArrays holds read-only float64 arrays.
    from fuelhm_bench.io.flights import FlightArrays

    f = flights[0]
    fa = FlightArrays(flight_id=f.flight_id, unit_id=f.unit_id, time_s=f.time_s,
                      current_ma=f.current_ma, position_mm=f.position_mm)
    assert not fa.time_s.flags.writeable
    table = extract_table([fa])
    pd.testing.assert_frame_equal(table, extract_table([f]))


@pytest.mark.parametrize("case", ["empty", "text ids", "flagged"])
def test_column_dtypes_hold_for_every_table(flights, case):
    """Indicators float64, flags bool, counts int64, quality_reason object (never pandas' inferred string
    dtype), identifiers as pandas infers them (object when the table is empty), whatever the flights."""
    from fuelhm_bench.taxonomy import ALL_INDICATOR_NAMES

    good = flights[0]
    bad = Flight("bad-1", "ESN-1", good.time_s[::-1].copy(), good.current_ma, good.position_mm)
    chosen = {"empty": [], "text ids": flights[:2], "flagged": [good, bad]}[case]
    table = extract_table(chosen, on_error="flag")
    for name in ALL_INDICATOR_NAMES:
        assert table[name].dtype == np.float64 and table[f"{name}_valid"].dtype == bool, name
    assert table["n_points"].dtype == np.int64 and table["quality_reason"].dtype == object
    if case == "empty":
        assert table["flight_id"].dtype == object
    else:
        assert table["flight_id"].tolist() == [f.flight_id for f in chosen]
        assert table["unit_id"].tolist() == [f.unit_id for f in chosen]
