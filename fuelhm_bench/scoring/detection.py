"""Fault-detection KPIs: the paper's Table V, in both definitions, and results by band.

Counts follow the paper's condition assessment matrix (Fig. 9)::

                      estimated: no fault   estimated: fault
    actual: no fault        NFD                  FP
    actual: fault           FN                   FD

Rates (zero denominators give NaN and a note):

* ``fpr_standard  = FP / (FP + NFD)``  false alarms among healthy flights;
* ``fnr_standard  = FN / (FN + FD)``   missed detections among faulty flights;
* ``fpr_paper_def = FP / (FP + FD)``   the paper's Table III wording, "false
  positives among all the states where a fault is detected" (= 1 - precision);
* ``fnr_paper_def = FN / (FN + NFD)``  "false negatives among all the states
  where no fault is detected" (= false omission rate).

Only *detectable* faulty flights (intensity >= ``detectable_fraction`` of the
reference maximum) count as FN or FD; *incipient* ones are reported apart.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.scoring.intervals import per_unit_counts, pooled_rates
from fuelhm_bench.scoring.run import HEALTHY, MULTIPLE
from fuelhm_bench.scoring.thresholds import HealthyScoreModel
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["ALL_MODES", "METHOD_ALARM", "UNDEFINED_RATES", "detection_by_band", "detection_table", "modes_present",
           "operating_points"]

#: ``mode`` value of the rows pooling every flight.
ALL_MODES = "all"
#: ``operating_point`` of the method's own alarms.
METHOD_ALARM = "method_alarm"

_COUNTS = ["nfd", "fp", "fn", "fd", "n_healthy", "n_detectable", "n_detected", "n_not_detected",
           "n_incipient", "n_incipient_detected"]
_RATES = {
    "fpr_standard": ("fp", "n_healthy"),
    "fnr_standard": ("fn", "n_detectable"),
    "fpr_paper_def": ("fp", "n_detected"),
    "fnr_paper_def": ("fn", "n_not_detected"),
    "incipient_detection_rate": ("n_incipient_detected", "n_incipient"),
}
#: Why each rate is undefined (NaN) where it is: its denominator is 0.
UNDEFINED_RATES = {
    "fpr_standard": "no healthy flight",
    "fnr_standard": "no detectable faulty flight",
    "fpr_paper_def": "no detection: FP + FD = 0",
    "fnr_paper_def": "every flight detected: FN + NFD = 0",
}


def modes_present(flights: pd.DataFrame) -> list[str]:
    """Modes (in MODE_IDS order) that are the single active fault of at least one flight."""
    present = set(flights["true_mode"].unique())  # the few distinct values, not every flight's
    return [m for m in MODE_IDS if m in present]


def operating_points(flights: pd.DataFrame, model: HealthyScoreModel,
                     config: ScoringConfig) -> list[tuple[str, float, float, np.ndarray]]:
    """``(name, a, threshold, detected)`` for every ``A`` and for the method's own alarm.

    A flight is detected at ``A`` when ``score > mu + A * sigma`` (strictly).
    """
    score = flights["score"].to_numpy(dtype=float)
    points = [(config.operating_point_name(a), a, model.threshold(a), score > model.threshold(a))
              for a in config.a_values]
    points.append((METHOD_ALARM, np.nan, np.nan, flights["alarm"].to_numpy(dtype=bool)))
    return points


def _unit_counts(flights: pd.DataFrame, points, modes: list[str]) -> dict[str, np.ndarray]:
    """Per-unit counts of every (operating point, mode): ``{column: array (n_points * n_modes, n_units)}``.

    Rows are the (operating point, mode) pairs, point-major; columns the units in order of first
    appearance (the long table of one row per (point, mode, unit) that :func:`rates_with_intervals`
    would group). Columns: :data:`_COUNTS`. Counted with one ``bincount`` per column over all
    flights at once (a groupby per point and mode cost most of :func:`~fuelhm_bench.scoring.score_run`).
    """
    code, units = pd.factorize(flights["unit_id"], sort=False)  # -1: a missing unit id, left out as groupby does
    n_units = len(units)
    true_mode = flights["true_mode"].to_numpy(dtype=object)
    healthy = true_mode == HEALTHY
    detectable_any = flights["detectable"].to_numpy(dtype=bool)
    incipient_any = flights["incipient"].to_numpy(dtype=bool)
    one_row = np.zeros(len(code), dtype=np.int64)

    def per_unit(mask: np.ndarray) -> np.ndarray:
        return per_unit_counts(one_row, code, (1, n_units), mask)[0]

    members = {mode: ~healthy if mode == ALL_MODES else (true_mode == mode) & ~healthy for mode in modes}
    blocks = {c: [] for c in ("nfd", "fp", "fn", "fd", "n_incipient", "n_incipient_detected")}
    for _, _, _, detected in points:
        nfd, fp = per_unit(healthy & ~detected), per_unit(healthy & detected)
        for mode in modes:
            detectable = members[mode] & detectable_any
            incipient = members[mode] & incipient_any
            blocks["nfd"].append(nfd)
            blocks["fp"].append(fp)
            blocks["fn"].append(per_unit(detectable & ~detected))
            blocks["fd"].append(per_unit(detectable & detected))
            blocks["n_incipient"].append(per_unit(incipient))
            blocks["n_incipient_detected"].append(per_unit(incipient & detected))
    c = {name: np.array(parts, dtype=np.int64).reshape(len(parts), n_units) for name, parts in blocks.items()}
    c["n_healthy"] = c["fp"] + c["nfd"]
    c["n_detectable"] = c["fn"] + c["fd"]
    c["n_detected"] = c["fp"] + c["fd"]
    c["n_not_detected"] = c["fn"] + c["nfd"]
    return {name: c[name] for name in _COUNTS}


def _notes(table: pd.DataFrame) -> list[str]:
    """Per row, the undefined (NaN) rates of :data:`UNDEFINED_RATES` and why, ``"; "``-joined."""
    undefined = {rate: np.isnan(table[rate].to_numpy(dtype=float)) for rate in UNDEFINED_RATES}
    return ["; ".join(f"{rate} undefined ({why})" for rate, why in UNDEFINED_RATES.items() if undefined[rate][i])
            for i in range(len(table))]


def detection_table(flights: pd.DataFrame, model: HealthyScoreModel,
                    config: ScoringConfig | None = None) -> pd.DataFrame:
    """Table V: detection rates for every ``A`` (and the method's alarm) and every mode.

    For mode ``m`` the population is the healthy flights plus the flights
    where ``m`` is the only active fault; the ``"all"`` rows pool every flight
    (flights with several faults included).

    Parameters
    ----------
    flights : pandas.DataFrame
        Output of :func:`fuelhm_bench.scoring.flight_table`.
    model : HealthyScoreModel
        Gaussian fit of the healthy-training scores (thresholds).
    config : ScoringConfig or None, default=None

    Returns
    -------
    pandas.DataFrame
        One row per (operating point, mode): ``operating_point`` (``"thr(A=2)"``
        or ``"method_alarm"``), ``a``, ``threshold``, ``mode``, the counts
        ``nfd, fp, fn, fd, n_healthy, n_detectable, n_detected,
        n_not_detected, n_incipient, n_incipient_detected``, the rates
        ``fpr_standard, fnr_standard, fpr_paper_def, fnr_paper_def,
        incipient_detection_rate`` each with ``_ci_low``/``_ci_high`` (Wilson)
        and optionally ``_boot_low``/``_boot_high``, ``balanced_accuracy`` =
        ``1 - (fpr_standard + fnr_standard) / 2``, and ``note`` naming undefined
        rates.
    """
    config = ScoringConfig() if config is None else config
    points = operating_points(flights, model, config)
    modes = modes_present(flights) + [ALL_MODES]
    keys = {"operating_point": np.repeat(np.array([p[0] for p in points], dtype=object), len(modes)),
            "mode": np.tile(np.array(modes, dtype=object), len(points))}
    out = pooled_rates(keys, _unit_counts(flights, points, modes), rates=_RATES, confidence=config.confidence,
                       n_bootstrap=config.n_bootstrap, random_state=config.random_state)
    a_of = {config.operating_point_name(a): a for a in config.a_values}
    out.insert(1, "a", out["operating_point"].map(a_of).astype(float))
    out.insert(2, "threshold", [model.threshold(a_of[p]) if p in a_of else np.nan
                                for p in out["operating_point"]])
    out["balanced_accuracy"] = 1.0 - (out["fpr_standard"] + out["fnr_standard"]) / 2.0
    out["note"] = _notes(out)
    return out


def mode_band_groups(modes: np.ndarray, bands: np.ndarray, units: np.ndarray, mode_rank: dict[str, int],
                     band_rank: dict[str, int], keep: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """The (mode, band) rows and the unit columns of a per-unit table by mode and intensity band.

    Rows are in the order that a stable sort of the flights on ``mode_rank * 100 + band_rank`` (a mode
    or band without a rank last, in flight order) then ``groupby([mode, band], sort=False)`` gives;
    units are in order of first appearance in the per-unit table, one row per (mode, band, unit) in
    that order with the units of a (mode, band) in order of first appearance: the layout of
    :func:`~fuelhm_bench.scoring.intervals.pooled_rates`.

    Parameters
    ----------
    modes, bands, units : numpy.ndarray
        Mode, band and unit id of every flight (a missing unit id leaves the flight out).
    mode_rank, band_rank : dict of str to int
        Sort rank of each mode and band.
    keep : numpy.ndarray of bool or None, default=None
        Flights to count; None keeps every flight.

    Returns
    -------
    row, unit : numpy.ndarray of int
        Row and unit column of every flight (-1 for a flight left out; a flight without a unit id has
        the row of its mode and band when another flight makes it a row, and unit -1).
    row_mode, row_band : numpy.ndarray of object
        Mode and band of every row.
    n_units : int
        Number of unit columns.
    """
    unit_code, _ = pd.factorize(units, sort=False)
    kept = np.arange(len(units)) if keep is None else np.flatnonzero(keep)
    mode_code, mode_names = pd.factorize(modes[kept], sort=False)
    band_code, band_names = pd.factorize(bands[kept], sort=False)
    rank_m = np.array([mode_rank.get(m, np.nan) for m in mode_names], dtype=float)
    rank_b = np.array([band_rank.get(b, np.nan) for b in band_names], dtype=float)
    order = np.argsort(rank_m[mode_code] * 100 + rank_b[band_code], kind="stable")  # NaN last, as sort_values
    n_bands = max(len(band_names), 1)
    pair = (mode_code * n_bands + band_code)[order]
    at = kept[order]
    with_unit = unit_code[at] >= 0
    row_sorted, pairs = pd.factorize(pair[with_unit], sort=False)  # a row needs a flight with a unit id
    row_of_pair = np.full(len(mode_names) * n_bands, -1)
    row_of_pair[pairs] = np.arange(len(pairs))
    unit_sorted = unit_code[at[with_unit]]
    n_all = int(unit_code.max()) + 1 if len(unit_code) else 0
    cells, first = np.unique(row_sorted * n_all + unit_sorted, return_index=True)
    listed = unit_sorted[first[np.lexsort((first, cells // max(n_all, 1)))]]  # by row, then first appearance
    column_units = pd.unique(listed)
    column = np.full(n_all, -1)
    column[column_units] = np.arange(len(column_units))
    row, unit = np.full(len(units), -1), np.full(len(units), -1)
    row[at] = row_of_pair[pair]
    unit[at[with_unit]] = column[unit_sorted]
    pairs = np.asarray(pairs, dtype=np.int64)
    return (row, unit, np.asarray(mode_names, dtype=object)[pairs // n_bands],
            np.asarray(band_names, dtype=object)[pairs % n_bands], len(column_units))


def detection_by_band(flights: pd.DataFrame, model: HealthyScoreModel,
                      config: ScoringConfig | None = None) -> pd.DataFrame:
    """Detection rate per mode and intensity band, so incipient faults are visible.

    Parameters
    ----------
    flights : pandas.DataFrame
        Output of :func:`fuelhm_bench.scoring.flight_table`.
    model : HealthyScoreModel
    config : ScoringConfig or None, default=None

    Returns
    -------
    pandas.DataFrame
        One row per (operating point, mode, band) with ``n_flights``,
        ``n_detected``, ``detection_rate`` (+ intervals) and ``detectable``
        (whether the band lies wholly at or above ``detectable_fraction``). The
        ``"healthy"`` band rows give the false alarm rate; ``mode`` is
        ``"healthy"`` there. Multi-fault flights are excluded.
    """
    config = ScoringConfig() if config is None else config
    single = ~np.isin(flights["true_mode"].to_numpy(), [MULTIPLE])
    row, unit, row_mode, row_band, n_units = mode_band_groups(
        flights["true_mode"].to_numpy(dtype=object), flights["band"].to_numpy(dtype=object),
        flights["unit_id"].to_numpy(), {m: i for i, m in enumerate((HEALTHY, *MODE_IDS))},
        {b: i for i, b in enumerate((HEALTHY, *config.band_names))}, keep=single)
    points = operating_points(flights, model, config)
    shape = (len(row_mode), n_units)
    n_flights = per_unit_counts(row, unit, shape)
    counts = {"n_flights": np.concatenate([n_flights] * len(points)),
              "n_detected": np.concatenate([per_unit_counts(row, unit, shape, detected)
                                            for _, _, _, detected in points])}
    keys = {"operating_point": np.repeat(np.array([p[0] for p in points], dtype=object), len(row_mode)),
            "mode": np.tile(row_mode, len(points)), "band": np.tile(row_band, len(points))}
    out = pooled_rates(keys, counts, rates={"detection_rate": ("n_detected", "n_flights")},
                       confidence=config.confidence, n_bootstrap=config.n_bootstrap,
                       random_state=config.random_state)
    if not len(out):  # no flight with at most one fault: the point names are text, as the grouped long table's
        out["operating_point"] = out["operating_point"].astype(pd.Series([METHOD_ALARM]).dtype)
    lower_edge = dict(zip(config.band_names, (0.0, *config.band_edges)))
    out["detectable"] = [b != HEALTHY and lower_edge[b] >= config.detectable_fraction
                         for b in out["band"]]
    return out
