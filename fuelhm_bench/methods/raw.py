"""The raw-flight input of methods that declare ``needs_raw = True``.

A raw-signal method receives, in ``fit(raw_flights=...)``, an iterable of
:class:`RawFlight` (the healthy training flights, yielded one at a time so that
memory stays bounded) and, with each decision, ``decide(row, raw=RawFlight)``:
the full-rate samples of the flight the row describes (no cap, no
resampling). The arrays are those of the data format (docs/data-format.md):
milliamperes and millimetres at the boundary.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterator

import numpy as np
import pandas as pd

from fuelhm_bench.errors import DataFormatError

__all__ = ["RAW_SIGNALS", "RawFlight", "iter_raw_flights"]

#: Signals of a raw flight: name -> unit.
RAW_SIGNALS: dict[str, str] = {"time_s": "s", "current_mA": "mA", "position_mm": "mm",
                               "demand_mm": "mm", "n2_pct": "%"}


@dataclass(frozen=True, eq=False)
class RawFlight:
    """The full-rate samples of one flight.

    Parameters
    ----------
    unit_id : int or str
    flight_index : int
        0-based index of the flight in the unit's life.
    time_s : numpy.ndarray of shape (n,)
        Sample times [s], strictly increasing.
    current_mA : numpy.ndarray of shape (n,)
        Servovalve command current [mA].
    position_mm : numpy.ndarray of shape (n,)
        Measured (LVDT) actuator position [mm].
    demand_mm : numpy.ndarray of shape (n,)
        Position demand of the controller [mm].
    n2_pct : numpy.ndarray of shape (n,)
        Engine high-pressure spool speed [% of nominal].

    Raises
    ------
    DataFormatError
        When an array is not 1-D of the common length >= 2, not finite, or
        the time is not strictly increasing.
    """

    unit_id: Any
    flight_index: int
    time_s: np.ndarray
    current_mA: np.ndarray
    position_mm: np.ndarray
    demand_mm: np.ndarray
    n2_pct: np.ndarray

    def __post_init__(self) -> None:
        n = None
        for name in RAW_SIGNALS:
            arr = np.array(getattr(self, name), dtype=np.float64, copy=True)
            if arr.ndim != 1 or arr.size < 2 or (n is not None and arr.size != n):
                raise DataFormatError(f"The '{name}' field of RawFlight must be a 1-D array of "
                                      f"{'the length of time_s' if n else 'at least 2 samples'}. "
                                      f"Got shape {arr.shape} instead.")
            if not np.all(np.isfinite(arr)):
                raise DataFormatError(f"The '{name}' field of RawFlight must be finite. Got "
                                      f"{int((~np.isfinite(arr)).sum())} non-finite samples.")
            n = arr.size
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if np.any(np.diff(self.time_s) <= 0):
            raise DataFormatError("The 'time_s' field of RawFlight must be strictly increasing.")

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.time_s.size)


def iter_raw_flights(samples: pd.DataFrame) -> Iterator[RawFlight]:
    """The flights of a long-format sample table, one :class:`RawFlight` at a time.

    Parameters
    ----------
    samples : pandas.DataFrame
        One row per sample with ``unit_id``, ``flight_index`` and the
        :data:`RAW_SIGNALS` columns (e.g. ``raw_test.parquet`` of
        ``fuelhm-bench export --raw``).

    Yields
    ------
    RawFlight
        In order of first appearance.
    """
    missing = [c for c in ("unit_id", "flight_index", *RAW_SIGNALS) if c not in samples.columns]
    if missing:
        raise DataFormatError(f"The raw sample table must have the columns "
                              f"{['unit_id', 'flight_index', *RAW_SIGNALS]}. Missing {missing}.")
    for (unit, k), g in samples.groupby(["unit_id", "flight_index"], sort=False):
        yield RawFlight(unit, int(k), *(g[c].to_numpy() for c in RAW_SIGNALS))
