"""Input checks shared by the diagnosis modules (tables in, float matrices out)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from fuelhm_bench.errors import (  # noqa: F401 (NotFittedError re-exported)
    DataFormatError,
    NotFittedError,
    OutputPathError,
    ParameterError,
    UnknownNameError,
    parameter_error,
)
from fuelhm_bench.taxonomy import ALL_INDICATOR_NAMES, INDICATOR_NAMES

#: Label of healthy flights in the ``mode`` column of a DOE table.
HEALTHY: str = "healthy"


def param_error(name: str, owner: str, allowed: str, given: object) -> ParameterError:
    """Build a :class:`ParameterError` with the scikit-learn message template.

    Parameters
    ----------
    name : str
        Parameter name, e.g. ``"shrinkage"``.
    owner : str
        Class or function that owns the parameter, e.g. ``"HealthyModel"``.
    allowed : str
        What the parameter must be, e.g. ``"a float in [0, 1] or 'auto'"``.
    given : object
        The offending value.

    Returns
    -------
    ParameterError
    """
    return parameter_error(name, owner, allowed, given)


def check_features(features: Iterable[str] | None, owner: str, name: str = "features") -> tuple[str, ...]:
    """Validate an indicator selection; ``None`` means the paper's ten (``INDICATOR_NAMES``).

    Names may also be extended indicators (``EXTENDED_INDICATOR_NAMES``).

    Parameters
    ----------
    features : iterable of str or None
        Indicator names.
    owner : str
        Function or class named in error messages.
    name : str, default="features"
        Parameter named in error messages.

    Returns
    -------
    tuple of str
        The selection, in the order given.

    Raises
    ------
    ParameterError
        Empty selection, duplicates, or not an iterable of strings.
    UnknownNameError
        A name that is not in ``INDICATOR_NAMES``.
    """
    if features is None:
        return INDICATOR_NAMES
    if isinstance(features, str) or not isinstance(features, Iterable):
        raise param_error(name, owner, "a sequence of indicator names or None", features)
    names = tuple(features)
    if not names or not all(isinstance(f, str) for f in names) or len(set(names)) != len(names):
        raise param_error(name, owner, "a non-empty sequence of distinct indicator names or None", features)
    unknown = [f for f in names if f not in ALL_INDICATOR_NAMES]
    if unknown:
        raise UnknownNameError(
            f"Unknown indicator name(s) {unknown} in the '{name}' parameter of {owner}; "
            f"allowed: {list(ALL_INDICATOR_NAMES)} (the paper's ten, then the extended indicators)."
        )
    return names


def check_dataframe(table: object, what: str) -> pd.DataFrame:
    """Raise :class:`DataFormatError` unless ``table`` is a DataFrame."""
    if not isinstance(table, pd.DataFrame):
        raise DataFormatError(f"The {what} must be a pandas DataFrame. Got {type(table).__name__} instead.")
    return table


def require_columns(table: pd.DataFrame, columns: Sequence[str], what: str) -> None:
    """Raise :class:`DataFormatError` naming every column of ``columns`` missing from ``table``."""
    missing = [c for c in columns if c not in table.columns]
    if missing:
        plural = "s" if len(missing) > 1 else ""
        raise DataFormatError(
            f"The {what} is missing required column{plural} {', '.join(repr(c) for c in missing)}; "
            f"it has columns {list(map(str, table.columns))}."
        )


def indicator_matrix(table: object, features: Sequence[str], what: str) -> np.ndarray:
    """Indicator values as a float matrix with NaN for missing values.

    Parameters
    ----------
    table : pandas.DataFrame or array-like of shape (n_rows, n_features)
        An indicator table (DataFrame with one column per indicator and
        optionally ``<name>_valid`` boolean columns) or a plain 2-D array whose
        columns are ``features`` in that order.
    features : sequence of str
        Indicator columns to extract.
    what : str
        Name of the table in error messages.

    Returns
    -------
    ndarray of shape (n_rows, n_features), float64
        A value is NaN when it is NaN in the table or when its
        ``<name>_valid`` column exists and is False.

    Raises
    ------
    DataFormatError
        Missing or non-numeric indicator column, wrong array shape, or an
        infinite value (a bug upstream, never a legitimate "missing").
    """
    if isinstance(table, pd.DataFrame):
        require_columns(table, features, what)
        columns = []
        for name in features:
            try:
                col = pd.to_numeric(table[name], errors="raise").to_numpy(dtype=np.float64, na_value=np.nan)
            except (TypeError, ValueError) as exc:
                raise DataFormatError(f"Column {name!r} of the {what} must be numeric ({exc}).") from None
            valid_col = f"{name}_valid"
            if valid_col in table.columns:
                if not pd.api.types.is_bool_dtype(table[valid_col]):
                    raise DataFormatError(
                        f"Column {valid_col!r} of the {what} must be boolean. Got dtype {table[valid_col].dtype} instead."
                    )
                valid = table[valid_col].to_numpy(dtype=bool, na_value=False)  # <NA> means not valid
                col = np.where(valid, col, np.nan)
            columns.append(col)
        x = np.column_stack(columns) if columns else np.empty((len(table), 0))
    else:
        try:
            x = np.array(table, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise DataFormatError(f"The {what} must be a DataFrame or a numeric 2-D array ({exc}).") from None
        if x.ndim != 2 or x.shape[1] != len(features):
            raise DataFormatError(
                f"The {what} must be a DataFrame or an array of shape (n_rows, {len(features)}) "
                f"with columns {list(features)}. Got shape {x.shape} instead."
            )
    bad = np.isinf(x)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise DataFormatError(
            f"The {what} has an infinite value in indicator {features[col]!r} (row {row}); "
            "use NaN for an indicator the extraction could not support."
        )
    return x


def check_output_path(path: Path) -> None:
    """Raise :class:`OutputPathError` unless the directory of ``path`` exists."""
    if not path.parent.is_dir():
        raise OutputPathError(f"Cannot write {str(path)!r}: directory {str(path.parent)!r} does not exist.")
