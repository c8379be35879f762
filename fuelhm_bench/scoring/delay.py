"""Detection delay, in flights, per degradation event (unit x mode).

An *event* is a (unit, mode) pair where the mode's intensity is > 0 on at
least one evaluated flight of the unit. With ``o`` the labelled onset flight
index, ``d`` the first flight index >= ``o`` whose intensity reaches
``detectable_fraction`` of the reference maximum, and ``k`` the first flight
index >= ``o`` with a method alarm:

* ``delay_from_onset = k - o`` (flights);
* ``delay_after_detectable = max(0, k - d)`` (flights of lateness once the
  fault is detectable; 0 when detected before it became detectable).

Alarms before ``o`` are false alarms (counted by the FPR), never detections.
Events without alarm at or after ``o`` are *not detected*: they get no delay
and are counted separately.

Averaging delays over detected events only rewards missing the hard events
(turning a miss into a late detection raises that mean). The *censored* delay
fixes this: ``delay_from_onset_censored`` is ``k - o`` for a detected event and
``n_observed = last evaluated flight index - o + 1`` (a lower bound of the
unknown delay) for a missed one. Its mean and median can only decrease when a
detection is made earlier or a miss becomes a detection; they are the
headline delay KPIs.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.scoring.detection import ALL_MODES
from fuelhm_bench.scoring.intervals import wilson_interval
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["delay_summary", "detection_delays"]

_EVENT_COLUMNS = ["unit_id", "mode", "onset_index", "detectable_index", "first_alarm_index",
                  "last_index", "detected", "delay_from_onset", "delay_after_detectable",
                  "delay_from_onset_censored", "n_false_alarms_before_onset"]


def detection_delays(flights: pd.DataFrame, config: ScoringConfig | None = None) -> pd.DataFrame:
    """One row per degradation event with its detection delay.

    Parameters
    ----------
    flights : pandas.DataFrame
        Output of :func:`fuelhm_bench.scoring.flight_table`.
    config : ScoringConfig or None, default=None

    Returns
    -------
    pandas.DataFrame
        Columns ``unit_id, mode, onset_index, detectable_index`` (NaN when the
        fault never becomes detectable within the evaluated flights),
        ``first_alarm_index`` (NaN when not detected), ``last_index`` (last
        evaluated flight of the unit), ``detected``, ``delay_from_onset``,
        ``delay_after_detectable`` (flights, NaN when not detected),
        ``delay_from_onset_censored`` (flights; ``last_index - onset_index + 1``
        when not detected) and ``n_false_alarms_before_onset``.
    """
    config = ScoringConfig() if config is None else config
    rows = []
    # The columns read once as arrays, each unit's rows in flight-table order (the unit order of
    # groupby(sort=False): first appearance); column lookups per unit and mode cost more than the rest.
    unit_ids = flights["unit_id"].to_numpy()
    codes, uniques = pd.factorize(unit_ids, sort=False)  # code -1: a missing unit id, left out as groupby does
    order = np.argsort(codes, kind="stable")
    order = order[codes[order] >= 0]
    rows_of = np.split(order, np.cumsum(np.bincount(codes[codes >= 0], minlength=len(uniques)))[:-1])
    index_all = flights["flight_index"].to_numpy()
    alarm_all = flights["alarm"].to_numpy(dtype=bool)
    fraction_all = {mode: flights[f"fraction_{mode}"].to_numpy(dtype=float) for mode in MODE_IDS}
    onset_all = {mode: flights[f"onset_{mode}"].to_numpy() for mode in MODE_IDS}
    for unit_id, at in zip(uniques, rows_of):
        idx = index_all[at]
        alarm = alarm_all[at]
        for mode in MODE_IDS:
            frac = fraction_all[mode][at]
            if not np.any(frac > 0):
                continue
            onset = int(onset_all[mode][at[0]])
            after = idx >= onset
            det_at = idx[after & (frac >= config.detectable_fraction) & (frac > 0)]
            alarm_at = idx[after & alarm]
            first = float(alarm_at[0]) if alarm_at.size else np.nan
            d = float(det_at[0]) if det_at.size else np.nan
            last = int(idx.max())
            rows.append({
                "unit_id": unit_id, "mode": mode, "onset_index": onset,
                "detectable_index": d, "first_alarm_index": first, "last_index": last,
                "detected": bool(alarm_at.size),
                "delay_from_onset": first - onset,
                "delay_from_onset_censored": first - onset if alarm_at.size
                else float(last - onset + 1),
                "delay_after_detectable": max(0.0, first - d) if not np.isnan(first + d)
                else np.nan,
                "n_false_alarms_before_onset": int(np.sum(alarm & (idx < onset))),
            })
    return pd.DataFrame(rows, columns=_EVENT_COLUMNS).astype(
        {"detected": bool, "onset_index": np.int64, "last_index": np.int64,
         "n_false_alarms_before_onset": np.int64})


def _stats(x: np.ndarray) -> tuple[float, float, float]:
    x = x[np.isfinite(x)]
    if x.size == 0:
        return np.nan, np.nan, np.nan
    return float(x.mean()), float(np.median(x)), float(np.quantile(x, 0.95))


def delay_summary(delays: pd.DataFrame, config: ScoringConfig | None = None) -> pd.DataFrame:
    """Delay statistics per mode and pooled (``"all"``).

    Parameters
    ----------
    delays : pandas.DataFrame
        Output of :func:`detection_delays`.
    config : ScoringConfig or None, default=None
        For the confidence level of ``detected_fraction``.

    Returns
    -------
    pandas.DataFrame
        Columns ``mode, n_events, n_detected, n_not_detected,
        n_never_detectable, n_not_detected_once_detectable,
        detected_fraction`` (+ Wilson interval), and mean / median / 95th
        percentile of ``delay_from_onset`` and ``delay_after_detectable`` over
        detected events (NaN when none; undetected events are never averaged
        in: they are the ``n_not_detected`` column), and of
        ``delay_from_onset_censored`` over all events.
    """
    config = ScoringConfig() if config is None else config
    rows = []
    # The columns read once as arrays and cut per mode (a boolean row selection of the frame per mode
    # cost more than the statistics).
    event_mode = delays["mode"].to_numpy(dtype=object)
    detected = delays["detected"].to_numpy(dtype=bool)
    detectable_all = np.isfinite(delays["detectable_index"].to_numpy(dtype=float))
    from_onset = delays["delay_from_onset"].to_numpy(dtype=float)
    after_detectable = delays["delay_after_detectable"].to_numpy(dtype=float)
    censored = delays["delay_from_onset_censored"].to_numpy(dtype=float)
    present = [m for m in MODE_IDS if m in set(pd.unique(event_mode))]
    for mode in [*present, ALL_MODES]:
        at = slice(None) if mode == ALL_MODES else event_mode == mode
        det = detected[at]
        detectable = detectable_all[at]
        o_mean, o_med, o_p95 = _stats(from_onset[at])
        d_mean, d_med, d_p95 = _stats(after_detectable[at])
        c_mean, c_med, c_p95 = _stats(censored[at])
        rows.append({"mode": mode, "n_events": len(det), "n_detected": int(det.sum()),
                     "n_not_detected": int((~det).sum()),
                     "n_never_detectable": int((~detectable).sum()),
                     "n_not_detected_once_detectable": int((~det & detectable).sum()),
                     "delay_from_onset_mean": o_mean, "delay_from_onset_median": o_med,
                     "delay_from_onset_p95": o_p95, "delay_after_detectable_mean": d_mean,
                     "delay_after_detectable_median": d_med,
                     "delay_after_detectable_p95": d_p95,
                     "delay_from_onset_censored_mean": c_mean,
                     "delay_from_onset_censored_median": c_med,
                     "delay_from_onset_censored_p95": c_p95})
    out = pd.DataFrame(rows)
    k, n = out["n_detected"].to_numpy(float), out["n_events"].to_numpy(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(n > 0, k / np.where(n > 0, n, 1), np.nan)
    low, high = wilson_interval(k, n, confidence=config.confidence)
    out.insert(6, "detected_fraction", frac)
    out.insert(7, "detected_fraction_ci_low", low)
    out.insert(8, "detected_fraction_ci_high", high)
    return out
