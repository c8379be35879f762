"""Batch extraction over recorded flights (vectorised NumPy), and the indicator table.

:func:`velocity_gain_curve` bins a whole flight at once, with one of two engines:

* ``"numpy"``: an independent vectorised implementation of what
  :class:`~fuelhm_bench.indicators.StreamingExtractor` does sample by sample (same formulas,
  same floating-point order, same summation order: ``np.bincount`` adds in sample order);
* ``"numba"`` (default): the streaming extractor's compiled kernel run over the whole flight
  (about ten times faster, and it also supports observed stroke/current limits).

Both hand the resulting :class:`~fuelhm_bench.indicators.VelocityGainCurve` to the shared
:func:`~fuelhm_bench.indicators.indicators_from_curve`.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Literal

import numpy as np
import pandas as pd

from fuelhm_bench.errors import DataFormatError, ParameterError
from fuelhm_bench.indicators.config import (
    BAND_CELL_BINS,
    N_ACCUMULATORS,
    N_BAND_ACCUMULATORS,
    ExtractionConfig,
)
from fuelhm_bench.indicators.curve import COUNTER_NAMES, VelocityGainCurve
from fuelhm_bench.indicators.indicators import indicators_from_curve
from fuelhm_bench.indicators.inputs import flight_label, validate_flight, validate_n2
from fuelhm_bench.indicators.kernel import accumulate_flight, band_cell_width_ma
from fuelhm_bench.indicators.result import IndicatorResult, table_columns
from fuelhm_bench.indicators.velocity import (
    CURRENT_LIMIT,
    END_STOP,
    FAST_CURRENT,
    GAP,
    OUT_OF_RANGE,
    USED,
    classify_samples,
    resolve_zones,
    window_slope,
)
from fuelhm_bench.taxonomy import INDICATOR_NAMES
from fuelhm_bench.taxonomy import ALL_INDICATOR_NAMES


def velocity_points(time_s: object, current_ma: object, position_mm: object,
                    config: ExtractionConfig | None = None, *, flight_id: object = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The raw (current, velocity) points of the velocity-gain curve (paper Fig. 4, dots).

    Parameters
    ----------
    time_s, current_ma, position_mm : array_like
        Time stamps (s), control current (mA), LVDT position (mm).
    config : ExtractionConfig, optional
        Extraction configuration (default :class:`ExtractionConfig()`).
    flight_id : object, optional
        Flight identifier used in error messages.

    Returns
    -------
    tuple of numpy.ndarray
        Matched current (mA, see :mod:`~fuelhm_bench.indicators.velocity`) and velocity
        (mm/s) of the samples that enter the curve (not masked).

    Raises
    ------
    DataFormatError
        On malformed arrays (see :func:`~fuelhm_bench.indicators.inputs.validate_flight`).
    """
    cfg = ExtractionConfig() if config is None else config
    t, i, x = validate_flight(time_s, current_ma, position_mm, window=cfg.window_length,
                              flight_id=flight_id)
    v, i_m = window_slope(t, x, cfg.diff_half_width, i)
    cat = classify_samples(t, i, x, i_m, cfg, resolve_zones(cfg, i, x))
    used = cat == USED
    return i_m[used], v[used]


def _check_engine(engine: object, owner: str) -> None:
    if engine not in ("numba", "numpy"):
        raise ParameterError(
            f"The 'engine' parameter of {owner} must be 'numba' or 'numpy'. Got {engine!r} "
            f"instead."
        )


def velocity_gain_curve(time_s: object, current_ma: object, position_mm: object,
                        config: ExtractionConfig | None = None, *, flight_id: object = None,
                        engine: Literal["numba", "numpy"] = "numba",
                        n2_pct: object = None) -> VelocityGainCurve:
    """Binned velocity-gain curve of one recorded flight (batch).

    Parameters
    ----------
    time_s : array_like
        Strictly increasing time stamps, in s (any frame rate; the differentiator uses them).
    current_ma : array_like
        Servovalve control current, in mA.
    position_mm : array_like
        LVDT cylinder position, in mm.
    config : ExtractionConfig, optional
        Extraction configuration (default :class:`ExtractionConfig()`).
    flight_id : object, optional
        Flight identifier used in error messages.
    engine : {"numba", "numpy"}, default="numba"
        ``"numba"`` runs the compiled per-sample kernel of the streaming extractor over the
        whole flight (fast); ``"numpy"`` is the independent vectorised reference
        implementation. Both give the same sums (tested to agree bit for bit on the
        platforms we run; the contract is agreement to 1e-12 relative).
    n2_pct : array_like, optional
        Engine HP speed N2, in %, one value per sample (NaN: missing sample). It sorts the idle
        samples into the supply-pressure bands of the extended indicators ``Hys_lo``,
        ``Hys_hi`` and ``I0_slope``; without it those three are invalid.

    Returns
    -------
    VelocityGainCurve

    Raises
    ------
    DataFormatError
        Mismatched lengths, fewer samples than one differentiator window, NaN/inf values,
        time not strictly increasing, constant current, non-numeric input, or a malformed
        ``n2_pct``.
    ParameterError
        Unknown ``engine``.
    """
    _check_engine(engine, "velocity_gain_curve")
    cfg = ExtractionConfig() if config is None else config
    t, i, x = validate_flight(time_s, current_ma, position_mm, window=cfg.window_length,
                              flight_id=flight_id)
    n2 = validate_n2(n2_pct, len(t), flight_id)
    zones = resolve_zones(cfg, i, x)
    if engine == "numba":
        acc, counters, band = accumulate_flight(t, i, x, cfg, zones, n2)
        return VelocityGainCurve(config=cfg, accumulators=acc, counters=counters,
                                 band_accumulators=band)
    h = cfg.diff_half_width
    n = len(t)
    v, i_m = window_slope(t, x, h, i)
    cat = classify_samples(t, i, x, i_m, cfg, zones)
    used = cat == USED
    i_c = i_m[used]
    v_u = v[used]
    low, _ = cfg.current_range_ma
    n_bins = cfg.n_bins
    k = ((i_c - low) * (1.0 / cfg.bin_width_ma)).astype(np.int64)
    np.minimum(k, n_bins - 1, out=k)
    centre = low + (k + 0.5) * cfg.bin_width_ma
    idle = np.abs(v_u) <= cfg.idle_velocity_mm_s
    k_idle = k[idle]
    di = i_c[idle] - centre[idle]
    acc = np.zeros((N_ACCUMULATORS, n_bins))
    acc[0] = np.bincount(k, minlength=n_bins)
    acc[1] = np.bincount(k, weights=v_u, minlength=n_bins)
    acc[2] = np.bincount(k, weights=v_u * v_u, minlength=n_bins)
    acc[3] = np.bincount(k_idle, minlength=n_bins)
    acc[4] = np.bincount(k_idle, weights=v_u[idle], minlength=n_bins)
    acc[5] = np.bincount(k_idle, weights=di, minlength=n_bins)
    acc[6] = np.bincount(k_idle, weights=di * di, minlength=n_bins)
    band = np.zeros((N_BAND_ACCUMULATORS, cfg.n_band_cells))
    if n2 is not None:
        n2_idle = n2[h:n - h][used][idle]
        cell = k_idle // BAND_CELL_BINS
        dc = i_c[idle] - (low + (cell + 0.5) * band_cell_width_ma(cfg))
        n2_low, n2_high = cfg.pressure_bands_n2_pct
        for r, in_band in ((0, n2_idle < n2_low), (4, n2_idle >= n2_high)):
            j = cell[in_band]
            band[r] = np.bincount(j, minlength=cfg.n_band_cells)
            band[r + 1] = np.bincount(j, weights=dc[in_band], minlength=cfg.n_band_cells)
            band[r + 2] = np.bincount(j, weights=dc[in_band] * dc[in_band], minlength=cfg.n_band_cells)
            band[r + 3] = np.bincount(j, weights=n2_idle[in_band], minlength=cfg.n_band_cells)
    per_cat = np.bincount(cat, minlength=6)
    counters = dict.fromkeys(COUNTER_NAMES, 0)
    counters.update(n_samples=n, n_edge=2 * h, n_gap=per_cat[GAP], n_end_stop=per_cat[END_STOP],
                    n_current_limit=per_cat[CURRENT_LIMIT], n_out_of_range=per_cat[OUT_OF_RANGE],
                    n_fast_current=per_cat[FAST_CURRENT], n_used=per_cat[USED],
                    n_idle=int(idle.sum()))
    return VelocityGainCurve(config=cfg, accumulators=acc,
                             counters=np.array([counters[c] for c in COUNTER_NAMES]),
                             band_accumulators=band)


def extract_indicators(time_s: object, current_ma: object, position_mm: object,
                       config: ExtractionConfig | None = None, *, flight_id: object = None,
                       engine: Literal["numba", "numpy"] = "numba",
                       n2_pct: object = None) -> IndicatorResult:
    """Indicators of one recorded flight (batch).

    Equivalent to ``indicators_from_curve(velocity_gain_curve(...))``.

    Parameters
    ----------
    time_s, current_ma, position_mm : array_like
        Time stamps (s), control current (mA), LVDT position (mm).
    config : ExtractionConfig, optional
        Extraction configuration (default :class:`ExtractionConfig()`).
    flight_id : object, optional
        Flight identifier used in error messages.
    engine : {"numba", "numpy"}, default="numba"
        Binning implementation (see :func:`velocity_gain_curve`).
    n2_pct : array_like, optional
        Engine HP speed N2 (%) per sample (see :func:`velocity_gain_curve`).

    Returns
    -------
    IndicatorResult

    Raises
    ------
    DataFormatError
        On malformed arrays (see :func:`velocity_gain_curve`).

    Examples
    --------
    >>> from fuelhm_bench.indicators import extract_indicators
    >>> from fuelhm_bench.testing.indicators import DualGainCurve, synthetic_flight
    >>> f = synthetic_flight(DualGainCurve(), n_excursions=200, seed=1)
    >>> r = extract_indicators(f.time_s, f.current_ma, f.position_mm)
    >>> r.all_valid, abs(r.values["Inb"] - 0.5) < 0.05
    (True, True)
    """
    curve = velocity_gain_curve(time_s, current_ma, position_mm, config, flight_id=flight_id,
                                engine=engine, n2_pct=n2_pct)
    return indicators_from_curve(curve)


def _recorded_n2(flight: object) -> object:
    """A flight's N2 (%): its ``n2_pct`` attribute, else ``extras["n2_pct"]``, else None."""
    n2 = getattr(flight, "n2_pct", None)
    if n2 is None:
        extras = getattr(flight, "extras", None)
        if isinstance(extras, dict):
            n2 = extras.get("n2_pct")
    return n2


def extract_table(flights: Iterable[object], config: ExtractionConfig | None = None, *,
                  on_error: Literal["raise", "flag"] = "raise",
                  engine: Literal["numba", "numpy"] = "numba") -> pd.DataFrame:
    """Indicator table of many flights: one row per flight.

    Parameters
    ----------
    flights : iterable
        Objects with attributes ``flight_id``, ``time_s``, ``current_ma``, ``position_mm``
        (NumPy arrays) and optionally ``unit_id`` and ``n2_pct`` (engine HP speed, %, per sample;
        None or absent: not recorded) (e.g. ``fuelhm_bench.io.flights.FlightArrays``).
    config : ExtractionConfig, optional
        Extraction configuration (default :class:`ExtractionConfig()`).
    on_error : {"raise", "flag"}, default="raise"
        What to do with a malformed flight: raise its
        :class:`~fuelhm_bench.errors.DataFormatError`, or keep a row with every indicator
        invalid and the error message in ``quality_reason``.
    engine : {"numba", "numpy"}, default="numba"
        Binning implementation (see :func:`velocity_gain_curve`).

    Returns
    -------
    pandas.DataFrame
        Columns, in this order: ``flight_id``, ``unit_id`` (only when at least one flight has a
        non-None ``unit_id`` attribute), the ten indicators (float64, NaN when invalid),
        ``<name>_valid`` (bool) for the ten, the extended indicators
        (:data:`~fuelhm_bench.taxonomy.EXTENDED_INDICATOR_NAMES`, float64) and their
        ``<name>_valid`` (bool), ``n_points`` (int64), ``quality_reason`` (str, ``""`` when all
        ten are valid). Units: :data:`~fuelhm_bench.taxonomy.INDICATOR_UNITS` and
        :data:`~fuelhm_bench.taxonomy.EXTENDED_INDICATOR_UNITS`.

    Raises
    ------
    DataFormatError
        A flight object lacks a required attribute, or (``on_error="raise"``) its arrays are
        malformed; the message names the flight.
    ParameterError
        ``on_error`` is not ``"raise"`` or ``"flag"``, or unknown ``engine``.
    """
    if on_error not in ("raise", "flag"):
        raise ParameterError(
            f"The 'on_error' parameter of extract_table must be 'raise' or 'flag'. "
            f"Got {on_error!r} instead."
        )
    _check_engine(engine, "extract_table")
    cfg = ExtractionConfig() if config is None else config
    rows: list[dict[str, object]] = []
    has_unit = False
    for position, flight in enumerate(flights):
        flight_id = getattr(flight, "flight_id", None)
        label = flight_label(flight_id) if flight_id is not None else f"flight #{position}"
        missing = [a for a in ("flight_id", "time_s", "current_ma", "position_mm")
                   if not hasattr(flight, a)]
        if missing:
            raise DataFormatError(
                f"{label}: object of type {type(flight).__name__} has no attribute(s) "
                f"{', '.join(missing)}; extract_table needs flight_id, time_s, current_ma, "
                f"position_mm (and optionally unit_id)."
            )
        unit_id = getattr(flight, "unit_id", None)
        has_unit = has_unit or unit_id is not None
        try:
            result = extract_indicators(flight.time_s, flight.current_ma, flight.position_mm,
                                        cfg, flight_id=flight_id, engine=engine,
                                        n2_pct=_recorded_n2(flight))
        except DataFormatError as exc:
            if on_error == "raise":
                raise
            result = IndicatorResult.invalid((str(exc),))
        rows.append({"flight_id": flight_id, "unit_id": unit_id, **result.to_row()})
    columns = table_columns(with_unit_id=has_unit)
    # Each column built once with its dtype (a frame of dicts, then one astype per column, cost more
    # than the indicators of a short flight); the identifiers keep pandas' own inference.
    dtypes = {name: np.float64 for name in ALL_INDICATOR_NAMES}
    dtypes.update({f"{name}_valid": bool for name in ALL_INDICATOR_NAMES})
    dtypes["n_points"] = np.int64
    data = {}
    for column in columns:
        values = [row[column] for row in rows]
        if column in dtypes:
            data[column] = np.array(values, dtype=dtypes[column])
        elif column == "quality_reason" or not rows:  # object: not the str (empty: float) pandas would infer
            data[column] = pd.Series(values, dtype=object)
        else:
            data[column] = values
    return pd.DataFrame(data, columns=columns)
