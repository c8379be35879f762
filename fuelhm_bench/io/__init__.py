"""Reading and writing benchmark data at the file boundary (units of the files: s, mA, mm).

The flight format is described in docs/data-format.md; see :mod:`fuelhm_bench.io.flights` for the
file-level and per-flight rules, and :mod:`fuelhm_bench.io.tables` for the
supported file formats and atomic writing.
"""

from fuelhm_bench.io.flights import (
    BENCH_PHASE,
    PLAUSIBLE_RANGES,
    DEFAULT_MAX_NAN_GAP,
    DEFAULT_MIN_CURRENT_RANGE_MA,
    DEFAULT_MIN_SAMPLES,
    NUMERIC_COLUMNS,
    OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS,
    FlightArrays,
    FlightRejection,
    FlightWriter,
    check_flight,
    check_plausibility,
    iter_flights,
    labels_path_for,
    read_flights,
    read_labels,
    split_flights,
    validate_flight_table,
    write_flights,
    write_labels,
)
from fuelhm_bench.io.tables import SUPPORTED_SUFFIXES

__all__ = [
    "BENCH_PHASE",
    "PLAUSIBLE_RANGES",
    "check_plausibility",
    "DEFAULT_MAX_NAN_GAP",
    "DEFAULT_MIN_CURRENT_RANGE_MA",
    "DEFAULT_MIN_SAMPLES",
    "NUMERIC_COLUMNS",
    "OPTIONAL_COLUMNS",
    "REQUIRED_COLUMNS",
    "SUPPORTED_SUFFIXES",
    "FlightArrays",
    "FlightRejection",
    "FlightWriter",
    "check_flight",
    "iter_flights",
    "labels_path_for",
    "read_flights",
    "read_labels",
    "split_flights",
    "validate_flight_table",
    "write_flights",
    "write_labels",
]
