"""Validation of the indicator tables a method receives, and of its output table."""

from __future__ import annotations

from typing import Iterable

import numpy as np
import pandas as pd

from fuelhm_bench.errors import DataFormatError
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

__all__ = ["DECISION_COLUMNS", "GUILT_COLUMNS", "check_indicator_table"]

#: Columns of the guilt probabilities in a decisions table, in MODE_IDS order.
GUILT_COLUMNS: tuple[str, ...] = tuple(f"guilt_{m}" for m in MODE_IDS)

#: Columns of a decisions table (:func:`run_unit`, :meth:`BaseMethod.decide_unit`).
DECISION_COLUMNS: tuple[str, ...] = ("unit_id", "flight_index", "score", "alarm", *GUILT_COLUMNS)


def check_indicator_table(table: object, *, name: str, owner: str,
                          keys: Iterable[str] = ()) -> pd.DataFrame:
    """Check that ``table`` is an indicator table (DataFrame with the indicator columns).

    Parameters
    ----------
    table : object
        The candidate table.
    name : str
        Argument name used in the message.
    owner : str
        Function or class name used in the message.
    keys : iterable of str, default=()
        Extra required columns (e.g. ``("unit_id", "flight_index")``).

    Returns
    -------
    pandas.DataFrame
        ``table`` itself (not a copy).

    Raises
    ------
    DataFormatError
        When it is not a DataFrame, is empty or misses a column.
    """
    if not isinstance(table, pd.DataFrame):
        raise DataFormatError(f"The '{name}' parameter of {owner} must be a pandas DataFrame. "
                              f"Got {type(table).__name__} instead.")
    required = [*keys, *INDICATOR_NAMES]
    missing = [c for c in required if c not in table.columns]
    if missing:
        raise DataFormatError(f"The '{name}' parameter of {owner} must have the columns "
                              f"{required}. Missing {missing}.")
    if len(table) == 0:
        raise DataFormatError(f"The '{name}' parameter of {owner} must have at least one row. "
                              f"Got an empty table instead.")
    for col in INDICATOR_NAMES:
        if not pd.api.types.is_numeric_dtype(table[col]):
            raise DataFormatError(f"The '{name}' parameter of {owner} must have numeric indicator "
                                  f"columns. Got dtype {table[col].dtype} for {col!r} instead.")
    return table


def empty_decisions() -> pd.DataFrame:
    """An empty decisions table with the right columns and dtypes."""
    data = {"unit_id": pd.Series([], dtype=object),
            "flight_index": np.array([], dtype=np.int64),
            "score": np.array([], dtype=np.float64),
            "alarm": np.array([], dtype=bool)}
    data.update({c: np.array([], dtype=np.float64) for c in GUILT_COLUMNS})
    return pd.DataFrame(data)
