"""Flight data I/O: the long flight format (docs/data-format.md), per-flight checks, labels tables.

This module is the data boundary of fuelhm-bench. Columns keep the units of the
file format -- seconds (``time_s``), milliamperes (``current_mA``), millimetres
(``position_mm``, ``demand_mm``), percent (``n2_pct``) and degrees Celsius
(``fuel_temp_degC``); conversion to SI is done by the modules that consume the
arrays.

Files are Parquet (``.parquet``, preferred), CSV (``.csv``) or gzip CSV
(``.csv.gz``), chosen by the suffix; see :mod:`fuelhm_bench.io.tables`.

File-level rules
----------------
Applied by :func:`read_flights` and :func:`validate_flight_table` (and by every
writer before writing). A violation raises
:class:`~fuelhm_bench.errors.DataFormatError` naming the file (or ``source``):

F1. The required columns ``flight_id, time_s, current_mA, position_mm`` are
    present (exact, case-sensitive names). The message names the missing
    column(s), lists the columns found, and suggests a column that differs only
    by case. Column names must be unique.
F2. ``time_s, current_mA, position_mm`` and the optional ``demand_mm, n2_pct,
    fuel_temp_degC`` are converted to float64. A value that is not a number
    is an error naming the column, the first bad row (0-based data row; for
    CSV also the line number) and the value. Empty cells / NaN are allowed here
    and handled per flight (rule P6). Date/time columns are refused (times are
    plain seconds).
F3. ``flight_id`` is int64 or string and never missing; ``unit_id`` (optional)
    is int64 or string and may be missing. Floats with integral values become
    int64; booleans, fractional numbers and columns mixing integers and strings
    are refused. CSV has no types, so a CSV id column whose values are all
    canonical integers (``"7"``, ``"-3"``; not ``"007"``) is read as int64,
    otherwise as strings.
F4. The optional columns ``unit_id, demand_mm, n2_pct, fuel_temp_degC, phase``
    are kept (``phase`` as strings); unknown extra columns are kept unchanged.
F5. :func:`read_flights` refuses a missing file, an unknown suffix, an empty
    file and a table without data rows.

Plausibility rules
------------------
Applied by :func:`read_flights` (and :func:`check_plausibility`) to the whole
file, so that a unit mistake is caught before it gives a silent, meaningless
result. A violation raises :class:`~fuelhm_bench.errors.DataFormatError`
naming the file, the column, the observed range and the likely mistake:

F6. Every finite value of a numeric column lies within its plausible range
    (:data:`PLAUSIBLE_RANGES`): ``time_s`` within +-1e5 s (a flight lasts at most
    24 h), ``current_mA`` within +-100 mA (the loop works within about +-12 mA),
    ``position_mm`` and ``demand_mm`` within +-1000 mm (the stroke is 60 mm),
    ``n2_pct`` in [-1, 200] %, ``fuel_temp_degC`` in [-100, 200] degC. Values
    1000 times too large are reported as the likely unit mistake (ms for s, uA
    for mA, um for mm), kelvin for degC, rpm for N2 percent; others (e.g. 1e30)
    as corrupt values.
    Samples of a virtual bench without end stops (``phase`` equal to
    :data:`BENCH_PHASE`, written by ``fuelhm-bench sweep``) are exempt for
    ``position_mm``.
F7. Columns in a unit too small (every value within a limit, but not all zero):
    ``current_mA`` within +-0.1 mA looks like amperes; ``position_mm`` and
    ``demand_mm`` within +-0.1 mm look like metres; ``n2_pct`` within +-1.5 %
    looks like a fraction of the rated speed instead of percent (a running
    engine is above 50 % at ground idle).
F8. The median interval between consecutive samples of a flight (over the
    flights of the file whose ``time_s`` never decreases) lies in [1e-4, 1] s,
    i.e. a sampling rate of 1 Hz to 10 kHz (the frame rates a scenario allows);
    a median interval of several seconds means times in milliseconds. Flights
    out of time order do not count (rule P4 rejects them, saying so).

Per-flight rules
----------------
Applied by :func:`split_flights` / :func:`check_flight`. A flight that breaks
one is returned as a :class:`FlightRejection` whose ``reason`` sentence names
the column, the problem and where (time and/or sample index); the other
flights are unaffected. Rules apply in this order:

P1. Grouping: rows are grouped by ``flight_id`` (flights in order of first
    appearance; a flight's samples need not be contiguous in the file). Within
    a flight, samples keep their file order: they are never re-sorted.
P2. A flight has at most one distinct non-missing ``unit_id`` (missing cells
    are ignored; no value at all gives ``unit_id=None``).
P3. ``time_s`` has no NaN and no infinite value.
P4. ``time_s`` never decreases (in file order). A decrease rejects the flight.
P5. Exactly repeated timestamps (consecutive equal ``time_s``): if the
    repeated samples agree on ``current_mA`` and ``position_mm`` (equal, or
    both NaN) the later duplicates are dropped, with their optional columns;
    if they disagree the flight is rejected (which sample is right is
    unknowable). After P4-P5, ``time_s`` is strictly increasing.
P6. At least ``min_samples`` samples (default 2, never fewer than 2) remain.
P7. ``current_mA`` and ``position_mm`` have no infinite value. Runs of up to
    ``max_nan_gap`` consecutive NaN samples (default 3) are filled by linear
    interpolation *in time* between the neighbouring valid samples; a run
    touching the start or end of the flight is filled with the nearest valid
    value (no extrapolation). A longer run -- or a column that is NaN
    everywhere -- rejects the flight, naming the run length and its time span.
    The optional numeric columns get the same short-gap filling, but longer
    NaN runs there are left as NaN (they are auxiliary signals). ``phase`` and
    unknown columns are untouched.
P8. The current must excite the loop: ``max(current_mA) - min(current_mA)``
    must exceed ``min_current_range_ma`` (default 0 mA, i.e. an exactly
    constant current is rejected).
P9. The position must not be exactly constant over the flight (a stuck or
    disconnected sensor: a real LVDT reading carries noise).

Labels
------
Ground truth is kept out of the measurements, in a separate table keyed by
``flight_id`` (one row per flight, ids unique) stored beside the flight file
under :func:`labels_path_for`: ``flights.parquet`` -> ``flights.labels.parquet``.

Writing
-------
Writers validate the table (rules F1-F4), refuse to replace an existing file
unless ``overwrite=True`` (``--force`` on the command line), create missing
parent directories, and publish atomically: data goes to a hidden temporary
file in the target directory, renamed onto the target only on success.
:class:`FlightWriter` streams chunks so that peak memory stays one chunk.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from fuelhm_bench.errors import DataFormatError, OutputPathError, range_error, show_value
from fuelhm_bench.io.tables import (
    AtomicTableWriter,
    check_output_path,
    read_table,
    table_format,
)

__all__ = [
    "BENCH_PHASE",
    "DEFAULT_MAX_NAN_GAP",
    "DEFAULT_MIN_CURRENT_RANGE_MA",
    "DEFAULT_MIN_SAMPLES",
    "NUMERIC_COLUMNS",
    "OPTIONAL_COLUMNS",
    "REQUIRED_COLUMNS",
    "FlightArrays",
    "FlightRejection",
    "FlightWriter",
    "PLAUSIBLE_RANGES",
    "check_flight",
    "check_plausibility",
    "iter_flights",
    "labels_path_for",
    "read_flights",
    "read_labels",
    "split_flights",
    "validate_flight_table",
    "write_flights",
    "write_labels",
]

#: Columns every flight table has (docs/data-format.md section 2).
REQUIRED_COLUMNS: tuple[str, ...] = ("flight_id", "time_s", "current_mA", "position_mm")
#: Optional columns with a meaning in docs/data-format.md; kept when present.
OPTIONAL_COLUMNS: tuple[str, ...] = ("unit_id", "demand_mm", "n2_pct", "fuel_temp_degC", "phase")
#: Columns stored as float64, with their units.
NUMERIC_COLUMNS: dict[str, str] = {
    "time_s": "s",
    "current_mA": "mA",
    "position_mm": "mm",
    "demand_mm": "mm",
    "n2_pct": "%",
    "fuel_temp_degC": "degC",
}
#: Optional columns carried in :attr:`FlightArrays.extras`.
EXTRA_COLUMNS: tuple[str, ...] = ("demand_mm", "n2_pct", "fuel_temp_degC", "phase")
#: Default of ``min_samples`` (rule P6): a flight needs two samples to have a time axis.
DEFAULT_MIN_SAMPLES: int = 2
#: Default of ``max_nan_gap`` (rule P7), in samples.
DEFAULT_MAX_NAN_GAP: int = 3
#: Default of ``min_current_range_ma`` (rule P8), in mA.
DEFAULT_MIN_CURRENT_RANGE_MA: float = 0.0

#: Phase value of samples recorded on a virtual bench without end stops (``fuelhm-bench sweep``):
#: the rod position is not limited to the stroke (rule F6) and no end-stop mask applies to it.
BENCH_PHASE: str = "bench_sweep"
#: Plausible range of each numeric column (rule F6), in the column's unit.
PLAUSIBLE_RANGES: dict[str, tuple[float, float]] = {
    "time_s": (-1e5, 1e5),
    "current_mA": (-100.0, 100.0),
    "position_mm": (-1000.0, 1000.0),
    "demand_mm": (-1000.0, 1000.0),
    "n2_pct": (-1.0, 200.0),
    "fuel_temp_degC": (-100.0, 200.0),
}
#: Rule F6: the likely mistake when values are 1000 times too large.
_TOO_LARGE_UNITS: dict[str, str] = {
    "time_s": "milliseconds instead of seconds (divide by 1000)",
    "current_mA": "microamperes instead of milliamperes (divide by 1000)",
    "position_mm": "micrometres instead of millimetres (divide by 1000)",
    "demand_mm": "micrometres instead of millimetres (divide by 1000)",
}
#: Rule F7: columns whose values all within +-limit are in a unit too small (1000 or 100 times).
_TOO_SMALL: dict[str, tuple[float, str]] = {
    "current_mA": (0.1, "amperes instead of milliamperes (multiply by 1000)"),
    "position_mm": (0.1, "metres instead of millimetres (multiply by 1000)"),
    "demand_mm": (0.1, "metres instead of millimetres (multiply by 1000)"),
    "n2_pct": (1.5, "a fraction of the rated speed instead of percent (multiply by 100)"),
}
#: Rule F7: what each column of :data:`_TOO_SMALL` measures, for its message.
_QUANTITY: dict[str, str] = {
    "current_mA": "current of the actuation loop",
    "position_mm": "position of the actuation loop",
    "demand_mm": "position demand of the actuation loop (stroke 60 mm)",
    "n2_pct": "engine core speed of a recording (ground idle is above 50 %)",
}
#: Rule F9: flights with fewer valid steps do not count in the sign-convention check.
_SIGN_MIN_STEPS: int = 100
#: Rule F9: the median correlation of current and rod velocity below which the file is refused.
_SIGN_MIN_CORRELATION: float = -0.3
#: Rule F8: plausible median sampling interval [s] (10 kHz to 1 Hz).
PLAUSIBLE_SAMPLING_S: tuple[float, float] = (1e-4, 1.0)

#: (column, FlightArrays attribute) of the two signals every flight must have.
_SIGNALS: tuple[tuple[str, str], ...] = (
    ("current_mA", "current_ma"),
    ("position_mm", "position_mm"),
)
_MAX_INT_DIGITS = 18  # canonical decimal integers that always fit in int64

FlightId = int | str


# ---------------------------------------------------------------------------
# Per-flight containers
# ---------------------------------------------------------------------------


def _readonly_1d(values: Any, dtype: Any) -> np.ndarray:
    """Return a read-only 1-D view of ``values`` (the caller's array keeps its flags)."""
    array = np.asarray(values, dtype=dtype).view()
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class FlightArrays:
    """The samples of one flight, as read-only 1-D arrays in file units.

    Parameters
    ----------
    flight_id : int or str
        The flight's identifier.
    unit_id : int, str or None
        The actuator / engine serial, or None when the table has none.
    time_s : array-like of float, shape (n_samples,)
        Time since the start of the flight, in s.
    current_ma : array-like of float, shape (n_samples,)
        Servovalve control current commanded by the controller, in mA
        (column ``current_mA``).
    position_mm : array-like of float, shape (n_samples,)
        Cylinder rod position measured by the LVDT, in mm.
    extras : dict of str to numpy.ndarray, default={}
        Optional columns present in the table, each of shape (n_samples,):
        ``demand_mm`` (mm), ``n2_pct`` (%), ``fuel_temp_degC`` (degC) as
        float64, ``phase`` as an object array of str (NaN when missing).

    Attributes
    ----------
    n_samples : int
        Number of samples.

    Notes
    -----
    Arrays are converted to read-only views (float64 for the numeric ones),
    so a flight cannot be altered after construction. Flights from
    :func:`iter_flights` are raw (file order, possibly NaN); flights from
    :func:`split_flights` / :func:`check_flight` satisfy rules P2-P9 (strictly
    increasing time, finite current and position).
    """

    flight_id: FlightId
    unit_id: FlightId | None
    time_s: np.ndarray
    current_ma: np.ndarray
    position_mm: np.ndarray
    extras: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        arrays = {
            name: _readonly_1d(getattr(self, name), np.float64)
            for name in ("time_s", "current_ma", "position_mm")
        }
        extras = {
            name: _readonly_1d(values, np.float64 if name in NUMERIC_COLUMNS else object)
            for name, values in self.extras.items()
        }
        shapes = {name: a.shape for name, a in {**arrays, **extras}.items()}
        if any(len(s) != 1 for s in shapes.values()) or len(set(shapes.values())) != 1:
            raise DataFormatError(
                f"FlightArrays of flight {self.flight_id!r}: all arrays must be 1-D with one "
                f"length. Got shapes {shapes} instead."
            )
        for name, array in arrays.items():
            object.__setattr__(self, name, array)
        object.__setattr__(self, "extras", extras)

    @property
    def n_samples(self) -> int:
        """Number of samples of the flight."""
        return int(self.time_s.shape[0])

    def _take(self, index: np.ndarray) -> FlightArrays:
        return FlightArrays(
            flight_id=self.flight_id,
            unit_id=self.unit_id,
            time_s=self.time_s[index],
            current_ma=self.current_ma[index],
            position_mm=self.position_mm[index],
            extras={name: values[index] for name, values in self.extras.items()},
        )


@dataclass(frozen=True)
class FlightRejection:
    """A flight left out by :func:`split_flights`, and why.

    Parameters
    ----------
    flight_id : int or str
        The rejected flight.
    unit_id : int, str or None
        Its unit, when known (None when absent or ambiguous).
    reason : str
        One sentence naming the column and the problem, e.g. ``"time_s
        decreases from 4 s to 3.9 s at sample 40 of the flight ..."``.
    source : str, default="<table>"
        The file (or table description) the flight came from.

    Examples
    --------
    >>> str(FlightRejection(7, "SN1", "Only 1 sample (at least 2 are required).", "f.csv"))
    "f.csv: flight 7 (unit 'SN1') rejected: Only 1 sample (at least 2 are required)."
    """

    flight_id: FlightId
    unit_id: FlightId | None
    reason: str
    source: str = "<table>"

    def __str__(self) -> str:
        unit = "" if self.unit_id is None else f" (unit {self.unit_id!r})"
        return f"{self.source}: flight {self.flight_id!r}{unit} rejected: {self.reason}"


# ---------------------------------------------------------------------------
# File-level validation
# ---------------------------------------------------------------------------


def _show(value: Any) -> str:
    """``repr`` of a value without numpy's type wrapper (``1.5``, not ``np.float64(1.5)``): :func:`show_value`."""
    return show_value(value, limit=200)


def _row_ref(row: int, first_line: int | None) -> str:
    line = "" if first_line is None else f", line {row + first_line} of the file"
    return f"row {row} (0-based data row{line})"


def _check_columns(frame: pd.DataFrame, source: str) -> None:
    names = [str(c) for c in frame.columns]
    repeated = sorted({c for c in names if names.count(c) > 1})
    if repeated:
        raise DataFormatError(f"Flight data '{source}' has repeated column names {repeated}.")
    missing = [c for c in REQUIRED_COLUMNS if c not in names]
    if missing:
        lower = {c.lower(): c for c in names}
        hints = [f"'{lower[m.lower()]}' for '{m}'" for m in missing if m.lower() in lower]
        hint = f" Column names are case-sensitive: found {', '.join(hints)}." if hints else ""
        raise DataFormatError(
            f"Flight data '{source}' is missing the required column(s) {missing}. "
            f"Required: {list(REQUIRED_COLUMNS)}; found columns: {names}.{hint}"
        )


def _to_float64(
    values: pd.Series, column: str, source: str, first_line: int | None
) -> np.ndarray:
    """Convert one numeric column to float64 or raise naming the first bad row."""
    dtype = values.dtype
    unit = NUMERIC_COLUMNS[column]
    if pd.api.types.is_datetime64_any_dtype(dtype) or pd.api.types.is_timedelta64_dtype(dtype):
        raise DataFormatError(
            f"Column '{column}' of '{source}' holds date/time values ({dtype}); it must hold "
            f"plain numbers in {unit}."
        )
    if pd.api.types.is_numeric_dtype(dtype) and not pd.api.types.is_bool_dtype(dtype):
        return values.to_numpy(dtype=np.float64, na_value=np.nan)
    numbers = pd.to_numeric(values, errors="coerce")
    bad = np.flatnonzero((numbers.isna() & values.notna()).to_numpy())
    if bad.size:
        row = int(bad[0])
        raise DataFormatError(
            f"Column '{column}' of '{source}' must hold numbers in {unit}: the value "
            f"{_show(values.iloc[row])} at {_row_ref(row, first_line)} is not a number "
            f"({bad.size} bad value(s) in the column)."
        )
    return numbers.to_numpy(dtype=np.float64, na_value=np.nan)


def _integer_ids(values: pd.Series, has_missing: bool) -> pd.Series:
    return values.astype("Int64" if has_missing else "int64")


def _normalize_ids(
    values: pd.Series, column: str, source: str, first_line: int | None, *, allow_missing: bool
) -> pd.Series:
    """Return an id column as int64 (Int64 if it has missing cells) or str (rule F3)."""
    missing = values.isna().to_numpy()
    if missing.any() and not allow_missing:
        row = int(np.flatnonzero(missing)[0])
        raise DataFormatError(
            f"Column '{column}' of '{source}' is missing at {_row_ref(row, first_line)} "
            f"({int(missing.sum())} missing value(s)); every sample needs a {column}."
        )
    dtype = values.dtype

    def refuse(row: int, what: str) -> DataFormatError:
        return DataFormatError(
            f"Column '{column}' of '{source}' must hold integers or strings: {what} at "
            f"{_row_ref(row, first_line)}."
        )

    if pd.api.types.is_bool_dtype(dtype):
        raise refuse(0, f"it holds booleans ({_show(values.iloc[0])})")
    if pd.api.types.is_integer_dtype(dtype):
        return _integer_ids(values, bool(missing.any()))
    if pd.api.types.is_float_dtype(dtype):
        numbers = values.to_numpy(dtype=np.float64, na_value=np.nan)
        fractional = np.flatnonzero(~missing & (np.mod(numbers, 1.0) != 0))
        if fractional.size:
            row = int(fractional[0])
            raise refuse(row, f"the value {_show(numbers[row])} is not an integer")
        return _integer_ids(values, bool(missing.any()))
    if isinstance(dtype, pd.StringDtype) or missing.all():
        return values.astype("str")
    objects = values.to_numpy(dtype=object)
    is_str = np.array([isinstance(v, str) for v in objects])
    is_int = np.array(
        [isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)) for v in objects]
    )
    if (is_str | missing).all():
        return values.astype("str")
    if (is_int | missing).all():
        return _integer_ids(values, bool(missing.any()))
    if ((is_str | is_int) | missing).all():
        row = int(np.flatnonzero(is_int if is_str[~missing][0] else is_str)[0])
        raise refuse(row, f"it mixes integers and strings ({_show(objects[row])})")
    row = int(np.flatnonzero(~(is_str | is_int | missing))[0])
    raise refuse(row, f"the value {_show(objects[row])} ({type(objects[row]).__name__})")


def _csv_ids(frame: pd.DataFrame, columns: tuple[str, ...]) -> pd.DataFrame:
    """Turn CSV id columns whose values are all canonical integers into integers (rule F3)."""
    pattern = rf"-?(0|[1-9][0-9]{{0,{_MAX_INT_DIGITS - 1}}})"
    converted = {}
    for column in columns:
        if column not in frame.columns:
            continue
        values = frame[column]
        present = values.dropna()
        if len(present) and present.astype("str").str.fullmatch(pattern).all():
            numbers = pd.to_numeric(values)
            converted[column] = _integer_ids(numbers, bool(values.isna().any()))
    return frame.assign(**converted) if converted else frame


def _require_frame(frame: object, source: str) -> None:
    if not isinstance(frame, pd.DataFrame):
        raise DataFormatError(
            f"Table '{source}' must be a pandas DataFrame. Got {type(frame).__name__} instead."
        )


def _validate_table(frame: pd.DataFrame, source: str, first_line: int | None) -> pd.DataFrame:
    _require_frame(frame, source)
    _check_columns(frame, source)
    frame = frame.reset_index(drop=True).set_axis([str(c) for c in frame.columns], axis=1)
    columns: dict[str, Any] = {
        name: _to_float64(frame[name], name, source, first_line)
        for name in NUMERIC_COLUMNS
        if name in frame.columns
    }
    columns["flight_id"] = _normalize_ids(
        frame["flight_id"], "flight_id", source, first_line, allow_missing=False
    )
    if "unit_id" in frame.columns:
        columns["unit_id"] = _normalize_ids(
            frame["unit_id"], "unit_id", source, first_line, allow_missing=True
        )
    if "phase" in frame.columns:
        columns["phase"] = frame["phase"].astype("str")
    return frame.assign(**columns)


def validate_flight_table(frame: pd.DataFrame, *, source: str = "<table>") -> pd.DataFrame:
    """Check a table against the file-level rules F1-F4 and normalize its types.

    Parameters
    ----------
    frame : pandas.DataFrame
        A long-format flight table (one row per sample). Not modified.
    source : str, default="<table>"
        Name of the table's origin, used in error messages.

    Returns
    -------
    pandas.DataFrame
        A copy with a ``RangeIndex``, float64 numeric columns (``time_s`` in s,
        ``current_mA`` in mA, ``position_mm`` in mm, ...), ``flight_id`` (and
        ``unit_id``) as int64 or str, ``phase`` as str; other columns unchanged
        and in the original order.

    Raises
    ------
    DataFormatError
        If a rule is broken; the message names ``source``, the column and,
        for bad values, the first offending row.
    """
    return _validate_table(frame, source, None)


# ---------------------------------------------------------------------------
# Files
# ---------------------------------------------------------------------------

_CSV_TEXT_DTYPES = {"flight_id": "str", "unit_id": "str", "phase": "str"}


def _first_line(path: Path) -> int | None:
    """Line number of the first data row in a CSV file (header on line 1), else None."""
    return None if table_format(path) == "parquet" else 2


def read_flights(path: str | os.PathLike[str]) -> pd.DataFrame:
    """Read a flight file (Parquet, CSV or gzip CSV) in the format of docs/data-format.md.

    Parameters
    ----------
    path : str or path-like
        ``*.parquet``, ``*.csv`` or ``*.csv.gz``.

    Returns
    -------
    pandas.DataFrame
        One row per sample, validated and normalized by the file-level rules
        F1-F4 (see :func:`validate_flight_table`): ``time_s`` in s,
        ``current_mA`` in mA, ``position_mm`` in mm as float64; optional and
        unknown columns kept. Per-flight rules are *not* applied here; use
        :func:`split_flights` on the result.

    Raises
    ------
    DataFormatError
        If the file is missing, empty, has an unsupported suffix, cannot be
        parsed, has no data rows or breaks a file-level rule. The message
        names the file and, where relevant, the column and row.

    Examples
    --------
    >>> table = read_flights("flights.parquet")  # doctest: +SKIP
    >>> flights, rejected = split_flights(table, source="flights.parquet")  # doctest: +SKIP
    """
    path = Path(path)
    frame = read_table(path, what="flight file", csv_dtypes=_CSV_TEXT_DTYPES)
    first_line = _first_line(path)
    if first_line is not None:
        frame = _csv_ids(frame, ("flight_id", "unit_id"))
    if len(frame) == 0:
        raise DataFormatError(
            f"The flight file '{path}' contains no samples: it has columns "
            f"{[str(c) for c in frame.columns]} but no data rows."
        )
    table = _validate_table(frame, str(path), first_line)
    check_plausibility(table, source=str(path))
    return table


def _range_text(values: np.ndarray) -> str:
    return f"[{values.min():.4g}, {values.max():.4g}]"


def check_plausibility(table: pd.DataFrame, *, source: str = "<table>") -> None:
    """Apply the plausibility rules F6-F9 to a validated flight table.

    Parameters
    ----------
    table : pandas.DataFrame
        A table normalized by :func:`validate_flight_table` (float64 columns).
    source : str, default="<table>"
        Name of the table's origin (normally the file), used in messages.

    Raises
    ------
    DataFormatError
        Naming ``source``, the column, the observed range, the plausible range
        and the likely unit mistake.
    """
    bench = (table["phase"] == BENCH_PHASE).to_numpy() if "phase" in table.columns else None
    for column, (lo, hi) in PLAUSIBLE_RANGES.items():
        if column not in table.columns:
            continue
        values = table[column].to_numpy()
        if bench is not None and column == "position_mm":
            values = values[~bench]
        values = values[np.isfinite(values)]
        if values.size == 0:
            continue
        unit = NUMERIC_COLUMNS[column]
        bad = (values < lo) | (values > hi)
        if bad.any():  # rule F6
            scaled = values / 1000.0
            if column in _TOO_LARGE_UNITS and ((scaled >= lo) & (scaled <= hi)).all():
                likely = f"It looks like {_TOO_LARGE_UNITS[column]}."
            elif column == "fuel_temp_degC" and ((values - 273.15 >= lo) & (values - 273.15 <= hi)).all():
                likely = "It looks like kelvin instead of degrees Celsius (subtract 273.15)."
            elif column == "n2_pct" and values.min() >= 0.0 and 1000.0 <= values.max() <= 100000.0:
                likely = ("It looks like revolutions per minute instead of percent of the reference speed "
                          "(divide by the reference speed in rpm, multiply by 100).")
            else:
                worst = values[bad][np.argmax(np.abs(values[bad]))]
                likely = (f"{int(bad.sum())} value(s) are out of range, the most extreme {worst:.4g} {unit}: "
                          "not a measurement (a corrupt file or a wrong column?).")
            if column == "position_mm":
                likely += (f" (Samples of a virtual bench without end stops must say so with phase "
                           f"'{BENCH_PHASE}'.)")
            raise DataFormatError(
                f"Column '{column}' of '{source}' ranges over {_range_text(values)} {unit}, outside its "
                f"plausible range [{lo:g}, {hi:g}] {unit}. {likely}")
        if column in _TOO_SMALL:  # rule F7
            limit, likely = _TOO_SMALL[column]
            magnitude = float(np.abs(values).max())
            if 0.0 < magnitude < limit:
                raise DataFormatError(
                    f"Column '{column}' of '{source}' ranges over only {_range_text(values)} {unit} (every "
                    f"value within +-{limit:g} {unit}): implausibly small for the {_QUANTITY[column]}. It looks "
                    f"like {likely}.")
    steps = _flight_steps(table)
    _check_sampling(table, steps, source)
    _check_sign_convention(table, steps, source)


class _FlightSteps(NamedTuple):
    """The steps between consecutive samples of each flight, shared by rules F8 and F9.

    ``codes``: each row's flight (0, 1, ... in order of first appearance); ``dt``: each row's time
    step from the previous sample of its flight [s] (NaN on a flight's first row); ``ordered``:
    whether the row's flight never steps back in time (a flight out of order says nothing to either
    rule; P4 rejects it with its own reason).
    """

    codes: np.ndarray
    dt: np.ndarray
    ordered: np.ndarray


def _flight_steps(table: pd.DataFrame) -> _FlightSteps:
    codes = pd.factorize(table["flight_id"], sort=False)[0]
    dt = table.groupby(codes, sort=False)["time_s"].diff().to_numpy()
    backwards = np.zeros(codes.max() + 1 if codes.size else 0, dtype=bool)
    np.logical_or.at(backwards, codes[dt < 0], True)
    return _FlightSteps(codes, dt, ~backwards[codes])


def _check_sign_convention(table: pd.DataFrame, steps: _FlightSteps, source: str) -> None:
    """Rule F9: positive current extends the rod, so current and rod velocity correlate positively.

    Per flight (in time order, with at least :data:`_SIGN_MIN_STEPS` finite steps), the Pearson
    correlation of the rod velocity ``d(position_mm)/dt`` with the current at mid-step; the file is
    refused when the median over those flights is below :data:`_SIGN_MIN_CORRELATION`.
    """
    codes, dt = steps.codes, steps.dt
    grouped = table.groupby(codes, sort=False)
    dx = grouped["position_mm"].diff().to_numpy()
    mid = 0.5 * (table["current_mA"].to_numpy() + grouped["current_mA"].shift().to_numpy())
    ok = np.isfinite(dt) & (dt > 0) & np.isfinite(dx) & np.isfinite(mid) & steps.ordered
    if not ok.any():
        return
    g, v, i = codes[ok], dx[ok] / dt[ok], mid[ok]
    n_groups = int(codes.max()) + 1

    def total(values: np.ndarray) -> np.ndarray:
        return np.bincount(g, weights=values, minlength=n_groups)

    n = np.bincount(g, minlength=n_groups).astype(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        mv, mi = total(v) / n, total(i) / n
        cov = total(v * i) / n - mv * mi
        var_v, var_i = total(v * v) / n - mv**2, total(i * i) / n - mi**2
        r = cov / np.sqrt(var_v * var_i)
    usable = (n >= _SIGN_MIN_STEPS) & (var_v > 0) & (var_i > 0) & np.isfinite(r)
    if not usable.any():
        return
    median = float(np.median(r[usable]))
    if median >= _SIGN_MIN_CORRELATION:
        return
    negative = int((r[usable] < 0).sum())
    raise DataFormatError(
        f"In '{source}' the rod velocity d(position_mm)/dt falls when current_mA rises: their correlation is "
        f"{median:.2f} (median over {int(usable.sum())} flight(s), negative in {negative}), where a positive "
        f"current extends the rod (position_mm increasing) and the two correlate at about +0.9. One of the two "
        f"columns has the opposite sign convention: negate current_mA, or give the position as measured from "
        f"the retracted end (stroke - position).")


def _check_sampling(table: pd.DataFrame, flight_steps: _FlightSteps, source: str) -> None:
    """Rule F8: the median interval between consecutive samples of a flight.

    Only flights whose ``time_s`` never decreases count: the steps of a flight out of time order
    (rows shuffled, a clock reset) say nothing about the unit of the column.
    """
    steps = flight_steps.dt
    steps = steps[np.isfinite(steps) & (steps > 0) & flight_steps.ordered]
    if steps.size == 0:
        return
    median = float(np.median(steps))
    lo, hi = PLAUSIBLE_SAMPLING_S
    if lo <= median <= hi:
        return
    likely = ("It looks like milliseconds instead of seconds (divide by 1000)." if median > hi else
              "Is the column in seconds? (hours or days give intervals this small)")
    raise DataFormatError(
        f"Column 'time_s' of '{source}' has a median sampling interval of {median:.4g} s (a rate of "
        f"{1.0 / median:.4g} Hz; time_s ranges over {_range_text(table['time_s'].dropna().to_numpy())} s), "
        f"outside the plausible [{lo:g}, {hi:g}] s (1 Hz to 10 kHz). {likely}")


def labels_path_for(path: str | os.PathLike[str]) -> Path:
    """Return the path of the labels table that goes with a flight file.

    The labels file sits beside the flight file, with ``.labels`` inserted
    before the format suffix.

    Parameters
    ----------
    path : str or path-like
        A flight file name (``.parquet``, ``.csv`` or ``.csv.gz``).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    DataFormatError
        If the suffix is not a supported one.

    Examples
    --------
    >>> labels_path_for("runs/flights.parquet").as_posix()
    'runs/flights.labels.parquet'
    >>> labels_path_for("x.csv.gz").name
    'x.labels.csv.gz'
    """
    path = Path(path)
    fmt = table_format(path)
    suffix_length = len(fmt) + 1
    stem, suffix = path.name[:-suffix_length], path.name[-suffix_length:]
    return path.with_name(f"{stem}.labels{suffix}")


def write_flights(
    frame: pd.DataFrame, path: str | os.PathLike[str], *, overwrite: bool = False
) -> Path:
    """Write a flight table to Parquet, CSV or gzip CSV, chosen by the suffix.

    Parameters
    ----------
    frame : pandas.DataFrame
        Long-format flight table; validated by the file-level rules F1-F4 and
        written normalized (float64 signals in s / mA / mm). Its index is not
        written. Must have at least one row.
    path : str or path-like
        Target ``*.parquet``, ``*.csv`` or ``*.csv.gz``; parent directories
        are created.
    overwrite : bool, default=False
        Replace an existing file. Without it an existing file is an error.

    Returns
    -------
    pathlib.Path
        The written path.

    Raises
    ------
    DataFormatError
        If ``frame`` breaks a file-level rule or has no rows.
    OutputPathError
        If the file exists and ``overwrite`` is false, or the path cannot be
        written. The message names the path.

    Notes
    -----
    The file appears atomically: an interrupted write leaves no partial file.
    """
    path = Path(path)
    table = _validate_table(frame, f"<table written to {path}>", None)
    return _write_table_atomically(table, path, overwrite=overwrite, what="flight file")


def _write_table_atomically(
    table: pd.DataFrame, path: Path, *, overwrite: bool, what: str
) -> Path:
    writer = AtomicTableWriter(path, overwrite=overwrite, what=what)
    try:
        writer.append(table)
    except BaseException:
        writer.abort()
        raise
    return writer.commit()


def _validate_labels(frame: pd.DataFrame, source: str, first_line: int | None) -> pd.DataFrame:
    _require_frame(frame, source)
    names = [str(c) for c in frame.columns]
    if "flight_id" not in names:
        raise DataFormatError(
            f"Labels table '{source}' is missing the required column 'flight_id'; "
            f"found columns: {names}."
        )
    frame = frame.reset_index(drop=True).set_axis(names, axis=1)
    columns = {
        "flight_id": _normalize_ids(
            frame["flight_id"], "flight_id", source, first_line, allow_missing=False
        )
    }
    if "unit_id" in names:
        columns["unit_id"] = _normalize_ids(
            frame["unit_id"], "unit_id", source, first_line, allow_missing=True
        )
    frame = frame.assign(**columns)
    _check_unique_labels(frame["flight_id"], source, first_line)
    return frame


def _check_unique_labels(ids: pd.Series, source: str, first_line: int | None) -> None:
    repeated = np.flatnonzero(ids.duplicated(keep=False).to_numpy())
    if repeated.size:
        flight = ids.iloc[int(repeated[0])]
        rows = np.flatnonzero((ids == flight).to_numpy())
        raise DataFormatError(
            f"Labels table '{source}' has {rows.size} rows for flight_id {_show(flight)} "
            f"({', '.join(_row_ref(int(r), first_line) for r in rows[:3])}); a labels "
            "table has one row per flight."
        )


def write_labels(
    labels: pd.DataFrame, path: str | os.PathLike[str], *, overwrite: bool = False
) -> Path:
    """Write a labels (ground-truth) table keyed by ``flight_id``.

    Parameters
    ----------
    labels : pandas.DataFrame
        One row per flight with a ``flight_id`` column (unique, never missing,
        int64 or str) and any ground-truth columns (unit, degradation mode,
        intensity, onset flight, hidden effects, ...). Its index is not written.
    path : str or path-like
        Target file, usually ``labels_path_for(flights_path)``; parent
        directories are created.
    overwrite : bool, default=False
        Replace an existing file. Without it an existing file is an error.

    Returns
    -------
    pathlib.Path
        The written path.

    Raises
    ------
    DataFormatError
        If ``flight_id`` is missing, has missing or repeated values, or the
        table has no rows.
    OutputPathError
        If the file exists and ``overwrite`` is false, or cannot be written.
    """
    path = Path(path)
    table = _validate_labels(labels, f"<labels written to {path}>", None)
    return _write_table_atomically(table, path, overwrite=overwrite, what="labels file")


def read_labels(path: str | os.PathLike[str]) -> pd.DataFrame:
    """Read a labels (ground-truth) table written by :func:`write_labels`.

    Parameters
    ----------
    path : str or path-like
        ``*.parquet``, ``*.csv`` or ``*.csv.gz``.

    Returns
    -------
    pandas.DataFrame
        One row per flight; ``flight_id`` (and ``unit_id`` if present) as
        int64 or str (rule F3); other columns as stored.

    Raises
    ------
    DataFormatError
        If the file is missing, empty, unreadable, has no rows, lacks
        ``flight_id`` or repeats a flight. The message names the file.
    """
    path = Path(path)
    frame = read_table(path, what="labels file", csv_dtypes={"flight_id": "str", "unit_id": "str"})
    first_line = _first_line(path)
    if first_line is not None:
        frame = _csv_ids(frame, ("flight_id", "unit_id"))
    if len(frame) == 0:
        raise DataFormatError(f"The labels file '{path}' contains no rows.")
    return _validate_labels(frame, str(path), first_line)


# ---------------------------------------------------------------------------
# Splitting into flights
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _RawGroup:
    flight: FlightArrays
    units: tuple[FlightId, ...]  # distinct non-missing unit ids, in order of appearance


def _python_scalar(value: Any) -> FlightId:
    return value.item() if isinstance(value, np.generic) else value


def _groups(table: pd.DataFrame) -> Iterator[_RawGroup]:
    """Split a validated table by flight_id (rule P1), without any check."""
    codes, flight_ids = pd.factorize(table["flight_id"], sort=False)
    order = np.argsort(codes, kind="stable")
    ends = np.cumsum(np.bincount(codes, minlength=len(flight_ids)))
    columns = {
        "time_s": table["time_s"].to_numpy()[order],
        "current_ma": table["current_mA"].to_numpy()[order],
        "position_mm": table["position_mm"].to_numpy()[order],
    }
    extras = {
        name: table[name].to_numpy(dtype=object if name == "phase" else np.float64)[order]
        for name in EXTRA_COLUMNS
        if name in table.columns
    }
    if "unit_id" in table.columns:
        unit_codes, unit_ids = pd.factorize(table["unit_id"], sort=False)
        unit_codes = unit_codes[order]
    else:
        unit_codes, unit_ids = np.full(len(table), -1), []
    start = 0
    for k, end in enumerate(ends):
        rows = slice(start, int(end))
        present = unit_codes[rows][unit_codes[rows] >= 0]
        _, first = np.unique(present, return_index=True)
        units = tuple(_python_scalar(unit_ids[present[i]]) for i in sorted(first))
        flight = FlightArrays(
            flight_id=_python_scalar(flight_ids[k]),
            unit_id=units[0] if len(units) == 1 else None,
            **{name: values[rows] for name, values in columns.items()},
            extras={name: values[rows] for name, values in extras.items()},
        )
        yield _RawGroup(flight=flight, units=units)
        start = int(end)


def _several_units_reason(units: tuple[FlightId, ...]) -> str:
    return (
        f"Its samples carry {len(units)} different unit_id values "
        f"({', '.join(repr(u) for u in units[:5])}); a flight belongs to one unit. If flights are numbered "
        "per unit, make flight_id unique in the file (e.g. '<unit>-<flight>')."
    )


def iter_flights(frame: pd.DataFrame, *, source: str = "<table>") -> Iterator[FlightArrays]:
    """Split a flight table into flights, without per-flight checks.

    Parameters
    ----------
    frame : pandas.DataFrame
        Long-format flight table (e.g. from :func:`read_flights`); validated
        with the file-level rules first. Not modified.
    source : str, default="<table>"
        Name of the table's origin, used in error messages.

    Returns
    -------
    iterator of FlightArrays
        One item per flight, in order of first appearance (rule P1). Samples
        keep their file order, even if the flight's rows are interleaved with
        other flights'. Values are raw: NaN, decreasing or repeated times are
        left as they are (use :func:`split_flights` for checked flights).

    Raises
    ------
    DataFormatError
        Immediately, if the table breaks a file-level rule; during iteration,
        if a flight's samples carry several ``unit_id`` values (a
        :class:`FlightArrays` has one unit).
    """
    table = _validate_table(frame, source, None)

    def generate() -> Iterator[FlightArrays]:
        for group in _groups(table):
            if len(group.units) > 1:
                raise DataFormatError(
                    f"Flight {group.flight.flight_id!r} of '{source}': "
                    + _several_units_reason(group.units)
                )
            yield group.flight

    return generate()


def _check_parameters(min_samples: int, max_nan_gap: int, min_current_range_ma: float) -> None:
    if isinstance(min_samples, bool) or not isinstance(min_samples, (int, np.integer)) or (
        min_samples < 2
    ):
        raise range_error("min_samples", "an integer >= 2", min_samples)
    if isinstance(max_nan_gap, bool) or not isinstance(max_nan_gap, (int, np.integer)) or (
        max_nan_gap < 0
    ):
        raise range_error("max_nan_gap", "an integer >= 0", max_nan_gap)
    if (
        isinstance(min_current_range_ma, bool)
        or not isinstance(min_current_range_ma, (int, float, np.integer, np.floating))
        or not np.isfinite(min_current_range_ma)
        or min_current_range_ma < 0
    ):
        raise range_error("min_current_range_ma", "a finite number >= 0 (mA)", min_current_range_ma)


def split_flights(
    frame: pd.DataFrame,
    *,
    source: str = "<table>",
    min_samples: int = DEFAULT_MIN_SAMPLES,
    max_nan_gap: int = DEFAULT_MAX_NAN_GAP,
    min_current_range_ma: float = DEFAULT_MIN_CURRENT_RANGE_MA,
) -> tuple[list[FlightArrays], list[FlightRejection]]:
    """Split a flight table into checked flights and rejections.

    Parameters
    ----------
    frame : pandas.DataFrame
        Long-format flight table (e.g. from :func:`read_flights`). Not modified.
    source : str, default="<table>"
        Name of the table's origin, used in messages (usually the file path).
    min_samples : int, default=2
        Minimum number of samples of a flight after dropping repeated
        timestamps (rule P6); at least 2.
    max_nan_gap : int, default=3
        Longest run of consecutive NaN samples of ``current_mA`` /
        ``position_mm`` that is interpolated (rule P7), in samples; 0 rejects
        any NaN.
    min_current_range_ma : float, default=0.0
        A flight whose current spans no more than this, in mA, has no
        excitation and is rejected (rule P8).

    Returns
    -------
    flights : list of FlightArrays
        Accepted flights, cleaned by rules P5 and P7, in order of first
        appearance.
    rejections : list of FlightRejection
        Rejected flights with a one-sentence reason each, in the same order.

    Raises
    ------
    DataFormatError
        If the table breaks a file-level rule (F1-F4).
    ParameterError
        If a parameter is out of range.

    Examples
    --------
    >>> import pandas as pd
    >>> table = pd.DataFrame({"flight_id": [1, 1, 1, 2], "time_s": [0.0, 0.1, 0.2, 0.0],
    ...                       "current_mA": [0.0, 1.0, 0.5, 0.0],
    ...                       "position_mm": [10.0, 10.1, 10.2, 10.0]})
    >>> flights, rejections = split_flights(table)
    >>> [f.flight_id for f in flights], rejections[0].reason
    ([1], 'Only 1 sample (at least 2 are required).')
    """
    _check_parameters(min_samples, max_nan_gap, min_current_range_ma)
    table = _validate_table(frame, source, None)
    accepted: list[FlightArrays] = []
    rejected: list[FlightRejection] = []
    for group in _groups(table):
        if len(group.units) > 1:
            result: FlightArrays | str = _several_units_reason(group.units)
        else:
            result = _apply_rules(group.flight, min_samples, max_nan_gap, min_current_range_ma)
        if isinstance(result, str):
            rejected.append(
                FlightRejection(group.flight.flight_id, group.flight.unit_id, result, source)
            )
        else:
            accepted.append(result)
    return accepted, rejected


def check_flight(
    flight: FlightArrays,
    *,
    source: str = "<table>",
    min_samples: int = DEFAULT_MIN_SAMPLES,
    max_nan_gap: int = DEFAULT_MAX_NAN_GAP,
    min_current_range_ma: float = DEFAULT_MIN_CURRENT_RANGE_MA,
) -> FlightArrays | FlightRejection:
    """Apply the per-flight rules P3-P9 to one flight.

    Parameters
    ----------
    flight : FlightArrays
        A raw flight, e.g. from :func:`iter_flights`. Not modified.
    source : str, default="<table>"
        Origin of the flight, stored in a rejection.
    min_samples : int, default=2
        See :func:`split_flights`.
    max_nan_gap : int, default=3
        See :func:`split_flights`, in samples.
    min_current_range_ma : float, default=0.0
        See :func:`split_flights`, in mA.

    Returns
    -------
    FlightArrays or FlightRejection
        The cleaned flight (strictly increasing ``time_s`` in s, finite
        ``current_ma`` in mA and ``position_mm`` in mm), or the reason it is
        rejected.

    Raises
    ------
    ParameterError
        If a parameter is out of range.
    """
    _check_parameters(min_samples, max_nan_gap, min_current_range_ma)
    result = _apply_rules(flight, min_samples, max_nan_gap, min_current_range_ma)
    if isinstance(result, str):
        return FlightRejection(flight.flight_id, flight.unit_id, result, source)
    return result


def _apply_rules(
    flight: FlightArrays, min_samples: int, max_nan_gap: int, min_current_range_ma: float
) -> FlightArrays | str:
    """Rules P3-P9; return the cleaned flight or a rejection sentence."""
    reason = _time_problem(flight.time_s)
    if reason is not None:
        return reason
    deduplicated = _drop_repeated_times(flight)
    if isinstance(deduplicated, str):
        return deduplicated
    reason = _sample_count_problem(deduplicated.n_samples, flight.n_samples, min_samples)
    if reason is not None:
        return reason
    filled = _fill_nan_gaps(deduplicated, max_nan_gap)
    if isinstance(filled, str):
        return filled
    reason = _excitation_problem(filled.current_ma, min_current_range_ma)
    if reason is None:
        reason = _stuck_position_problem(filled.position_mm)
    return filled if reason is None else reason


def _seconds(t: float) -> str:
    return f"{t:g} s"


def _time_problem(time_s: np.ndarray) -> str | None:
    """Rules P3 (no NaN / inf) and P4 (never decreasing)."""
    for bad, what in ((np.isnan(time_s), "missing (NaN)"), (np.isinf(time_s), "infinite")):
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            return (
                f"time_s is {what} at {int(bad.sum())} sample(s), first at sample {first} of "
                "the flight (0-based, file order); every sample needs a finite time."
            )
    steps = np.diff(time_s)
    decreases = np.flatnonzero(steps < 0)
    if decreases.size:
        k = int(decreases[0]) + 1
        reason = (
            f"time_s decreases from {_seconds(time_s[k - 1])} to {_seconds(time_s[k])} at "
            f"sample {k} of the flight (0-based, file order; {decreases.size} decrease(s) in "
            "all); the samples of a flight must be in increasing time order."
        )
        forward = steps[steps > 0]
        if forward.size:  # say what the decreases look like
            typical = float(np.median(forward))
            largest = float(-steps[decreases].min())
            if largest < 0.5 * typical:
                reason += (f" Every decrease is under half the typical step ({largest:.3g} s at most, against "
                           f"{typical:.3g} s): timestamp jitter; give each sample its frame time (rounded to "
                           f"the recording's frame period).")
            else:
                reason += " If the rows are only out of order, sort each flight's samples by time_s."
        return reason
    return None


def _same(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a == b) | (np.isnan(a) & np.isnan(b))


def _drop_repeated_times(flight: FlightArrays) -> FlightArrays | str:
    """Rule P5: drop identical repeated samples, reject conflicting ones."""
    repeated = np.flatnonzero(np.diff(flight.time_s) == 0) + 1
    if repeated.size == 0:
        return flight
    for column, attribute in _SIGNALS:
        values = getattr(flight, attribute)
        conflict = repeated[~_same(values[repeated], values[repeated - 1])]
        if conflict.size:
            k = int(conflict[0])
            unit = NUMERIC_COLUMNS[column]
            return (
                f"time_s repeats {_seconds(flight.time_s[k])} with different {column} values "
                f"({_show(values[k - 1])} then {_show(values[k])} {unit}, at samples "
                f"{k - 1} and {k}); "
                "repeated timestamps are only accepted when their samples are identical."
            )
    keep = np.ones(flight.n_samples, dtype=bool)
    keep[repeated] = False
    return flight._take(keep)


def _sample_count_problem(n_samples: int, n_original: int, min_samples: int) -> str | None:
    """Rule P6."""
    if n_samples >= min_samples:
        return None
    dropped = n_original - n_samples
    after = f" after dropping {dropped} repeated timestamp(s)" if dropped else ""
    noun = "sample" if n_samples == 1 else "samples"
    return f"Only {n_samples} {noun}{after} (at least {min_samples} are required)."


def _nan_runs(missing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start index and length of each run of True in a boolean array."""
    edges = np.diff(np.concatenate(([0], missing.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    return starts, np.flatnonzero(edges == -1) - starts


def _interpolate(time_s: np.ndarray, values: np.ndarray, where: np.ndarray) -> np.ndarray:
    """Fill ``values[where]`` linearly in time from the non-NaN samples (nearest at the edges)."""
    valid = ~np.isnan(values)
    filled = values.copy()
    filled[where] = np.interp(time_s[where], time_s[valid], values[valid])
    return filled


def _short_runs(missing: np.ndarray, max_nan_gap: int) -> np.ndarray:
    starts, lengths = _nan_runs(missing)
    where = np.zeros_like(missing)
    for start, length in zip(starts[lengths <= max_nan_gap], lengths[lengths <= max_nan_gap]):
        where[start : start + length] = True
    return where


def _signal_problem(
    column: str, time_s: np.ndarray, values: np.ndarray, max_nan_gap: int
) -> str | None:
    """Rule P7 for a required signal: infinite values, all-NaN, over-long NaN runs."""
    infinite = np.isinf(values)
    if infinite.any():
        first = int(np.flatnonzero(infinite)[0])
        return (
            f"{column} is infinite at {int(infinite.sum())} sample(s), first at "
            f"t = {_seconds(time_s[first])}."
        )
    missing = np.isnan(values)
    if missing.all():
        return f"{column} is missing (NaN) in all {values.size} samples."
    starts, lengths = _nan_runs(missing)
    too_long = np.flatnonzero(lengths > max_nan_gap)
    if too_long.size:
        start, length = int(starts[too_long[0]]), int(lengths[too_long[0]])
        return (
            f"{column} is missing (NaN) for {length} consecutive samples from "
            f"t = {_seconds(time_s[start])} to t = {_seconds(time_s[start + length - 1])} "
            f"({too_long.size} such run(s)); at most {max_nan_gap} consecutive missing "
            "samples are interpolated."
        )
    return None


def _fill_nan_gaps(flight: FlightArrays, max_nan_gap: int) -> FlightArrays | str:
    """Rule P7: reject bad signals, interpolate short NaN runs (also in numeric extras)."""
    signals = {}
    for column, attribute in _SIGNALS:
        values = getattr(flight, attribute)
        reason = _signal_problem(column, flight.time_s, values, max_nan_gap)
        if reason is not None:
            return reason
        missing = np.isnan(values)
        if missing.any():
            values = _interpolate(flight.time_s, values, missing)
        signals[attribute] = values
    extras = {}
    for name, values in flight.extras.items():
        if name in NUMERIC_COLUMNS and np.isnan(values).any() and not np.isnan(values).all():
            where = _short_runs(np.isnan(values), max_nan_gap)
            extras[name] = _interpolate(flight.time_s, values, where) if where.any() else values
        else:
            extras[name] = values
    return FlightArrays(
        flight_id=flight.flight_id,
        unit_id=flight.unit_id,
        time_s=flight.time_s,
        extras=extras,
        **signals,
    )


def _excitation_problem(current_ma: np.ndarray, min_current_range_ma: float) -> str | None:
    """Rule P8: the current must vary by more than ``min_current_range_ma`` (mA)."""
    span = float(np.ptp(current_ma))
    if span > min_current_range_ma:
        return None
    if span == 0:
        return (
            f"current_mA is constant ({current_ma[0]:g} mA) over all {current_ma.size} "
            "samples: no excitation, the loop cannot be monitored."
        )
    return (
        f"current_mA spans only {span:g} mA over {current_ma.size} samples (more than "
        f"{min_current_range_ma:g} mA is required): no excitation, the loop cannot be monitored."
    )


def _stuck_position_problem(position_mm: np.ndarray) -> str | None:
    """Rule P9: a position exactly constant over the whole flight is a stuck or disconnected sensor."""
    if float(np.ptp(position_mm)) > 0.0:
        return None
    return (
        f"position_mm is constant ({position_mm[0]:g} mm) over all {position_mm.size} samples while "
        "the current varies: a stuck or disconnected position sensor (a real LVDT reading always "
        "carries noise)."
    )


# ---------------------------------------------------------------------------
# Streaming writer
# ---------------------------------------------------------------------------


class FlightWriter:
    """Stream a flight file (and its labels file) chunk by chunk, atomically.

    Use it as a context manager. Each :meth:`write` appends the rows of one
    chunk (e.g. one batch of simulated flights) and forgets them, so peak
    memory is one chunk whatever the number of flights. The first chunk fixes
    the columns (and the Parquet schema); a flight's rows may be spread over
    several chunks. :meth:`write_labels` streams the labels table the same
    way to ``labels_path_for(path)``.

    Both files are written to hidden temporary files in the target directory
    and renamed onto their targets only when the ``with`` block ends without
    an exception (or :meth:`close` is called). If the block raises, the
    temporary files are deleted and the targets are left as they were: no
    half-written file is ever found at ``path``.

    Parameters
    ----------
    path : str or path-like
        Target flight file (``.parquet``, ``.csv`` or ``.csv.gz``); parent
        directories are created.
    overwrite : bool, default=False
        Replace existing files. Without it, an existing flight file -- or an
        existing labels file beside it, which would otherwise end up paired
        with the new flights -- is an error, raised on construction (before
        any simulation work). With it, an existing labels file is replaced
        only if :meth:`write_labels` is called.

    Attributes
    ----------
    path : pathlib.Path
        The flight file.
    labels_path : pathlib.Path
        The labels file, ``labels_path_for(path)``.
    n_rows : int
        Sample rows written so far.

    Raises
    ------
    OutputPathError
        On construction, if a target exists while ``overwrite`` is false or
        the directory cannot be created or written to.

    Examples
    --------
    >>> with FlightWriter(tmp / "flights.parquet") as writer:  # doctest: +SKIP
    ...     for batch in simulate_in_batches():
    ...         writer.write(batch.samples)
    ...         writer.write_labels(batch.labels)
    """

    def __init__(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> None:
        self.path = Path(path)
        self.labels_path = labels_path_for(self.path)
        self._overwrite = overwrite
        check_output_path(self.path, overwrite=overwrite, what="flight file")
        check_output_path(self.labels_path, overwrite=overwrite, what="labels file")
        self._flights = AtomicTableWriter(self.path, overwrite=overwrite, what="flight file")
        self._labels: AtomicTableWriter | None = None
        self._label_ids: set[FlightId] = set()
        self._id_kinds: dict[str, str] = {}
        self._chunks: dict[str, int] = {"flights": 0, "labels": 0}
        self._closed = False

    @property
    def n_rows(self) -> int:
        """Sample rows written so far."""
        return self._flights.n_rows

    def __enter__(self) -> FlightWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if self._closed:
            return
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def _check_open(self) -> None:
        if self._closed:
            raise OutputPathError(f"The FlightWriter of '{self.path}' is already closed.")

    def _check_id_kind(self, table: pd.DataFrame, stream: str, source: str) -> None:
        kind = "integer" if pd.api.types.is_integer_dtype(table["flight_id"].dtype) else "string"
        expected = self._id_kinds.setdefault(stream, kind)
        if kind != expected:
            raise DataFormatError(
                f"{source}: flight_id holds {kind}s but the first chunk's held {expected}s; "
                "a file has one flight_id type."
            )

    def write(self, chunk: pd.DataFrame) -> None:
        """Append a chunk of sample rows to the flight file.

        Parameters
        ----------
        chunk : pandas.DataFrame
            Long-format rows (``time_s`` in s, ``current_mA`` in mA,
            ``position_mm`` in mm, ...); validated by the file-level rules and
            written normalized. Must have the first chunk's columns and
            ``flight_id`` type. Empty chunks are skipped.

        Raises
        ------
        DataFormatError
            If the chunk breaks a file-level rule or differs from the first
            chunk. The message names the chunk.
        OutputPathError
            If the writer is closed or the file system refuses the write.
        """
        self._check_open()
        self._chunks["flights"] += 1
        if len(chunk) == 0:
            return
        source = f"<chunk {self._chunks['flights']} written to {self.path}>"
        table = _validate_table(chunk, source, None)
        self._check_id_kind(table, "flights", source)
        self._flights.append(table)

    def write_labels(self, chunk: pd.DataFrame) -> None:
        """Append a chunk of label rows to the labels file beside the flight file.

        Parameters
        ----------
        chunk : pandas.DataFrame
            One row per flight with a ``flight_id`` column; a flight may not
            appear twice, in this chunk or an earlier one. Empty chunks are
            skipped.

        Raises
        ------
        DataFormatError
            If ``flight_id`` is missing or repeated, or the columns differ
            from the first labels chunk.
        OutputPathError
            If the writer is closed or the file system refuses the write.
        """
        self._check_open()
        self._chunks["labels"] += 1
        if len(chunk) == 0:
            return
        source = f"<labels chunk {self._chunks['labels']} written to {self.labels_path}>"
        table = _validate_labels(chunk, source, None)
        self._check_id_kind(table, "labels", source)
        ids = [_python_scalar(v) for v in table["flight_id"].to_numpy()]
        seen = sorted(self._label_ids.intersection(ids), key=str)
        if seen:
            raise DataFormatError(
                f"{source}: flight_id {seen[0]!r} already has a label row in an earlier chunk; "
                "a labels table has one row per flight."
            )
        if self._labels is None:
            self._labels = AtomicTableWriter(
                self.labels_path, overwrite=self._overwrite, what="labels file"
            )
        self._labels.append(table)
        self._label_ids.update(ids)

    def close(self) -> Path:
        """Finish both files and move them onto their targets.

        Returns
        -------
        pathlib.Path
            The flight file path.

        Raises
        ------
        DataFormatError
            If no sample row was written (nothing is created).
        OutputPathError
            If a target cannot be written; nothing is left behind.
        """
        self._check_open()
        self._closed = True
        writers = [w for w in (self._flights, self._labels) if w is not None]
        try:
            for writer in writers:
                writer.prepare()
            for writer in writers:
                writer.publish()
        except BaseException:
            for writer in writers:
                writer.abort()
            raise
        return self.path

    def abort(self) -> None:
        """Discard everything written; the target paths are left untouched."""
        self._closed = True
        for writer in (self._flights, self._labels):
            if writer is not None:
                writer.abort()
