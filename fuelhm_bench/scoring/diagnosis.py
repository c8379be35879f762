"""Diagnosis KPIs: the paper's Table VI, false classification rate, confusion matrix.

Only *alarmed* flights are diagnosed (the method's own ``alarm``), and only
single-fault flights have a true mode. A classification is correct when the
true mode has the unique largest guilt; a tie for the largest guilt is a false
classification (a method cannot earn credit with a uniform guilt vector).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from fuelhm_bench.methods.tables import GUILT_COLUMNS
from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.scoring.detection import ALL_MODES, mode_band_groups, modes_present
from fuelhm_bench.scoring.intervals import per_unit_counts, pooled_rates
from fuelhm_bench.scoring.run import HEALTHY, NO_ALARM, TIE
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["classification_table", "confusion_matrix", "diagnosis_table"]


def _guilt_means(flights: pd.DataFrame, row: np.ndarray, alarmed: np.ndarray, n_rows: int) -> dict[str, np.ndarray]:
    """Mean of every guilt column over the alarmed flights of each row (NaN for a row without one).

    A pandas groupby mean on the row numbers, flights in table order: the same sums (pandas' compensated
    summation, in that order) as the groupby on (true_mode, band) it replaces.
    """
    at = alarmed & (row >= 0)
    guilt = pd.DataFrame({c: flights[c].to_numpy(dtype=float)[at] for c in GUILT_COLUMNS})
    means = guilt.groupby(row[at], sort=False).mean().reindex(np.arange(n_rows))
    return {c: means[c].to_numpy(dtype=float) for c in GUILT_COLUMNS}


def diagnosis_table(flights: pd.DataFrame, config: ScoringConfig | None = None) -> pd.DataFrame:
    """Table VI: mean guilt of every mode per effective degradation and intensity band.

    Parameters
    ----------
    flights : pandas.DataFrame
        Output of :func:`fuelhm_bench.scoring.flight_table`.
    config : ScoringConfig or None, default=None
        Bands: ``config.band_names`` (default ``"<12.5%"``, ``"25%"``, ``"50%"``,
        ``"100%"`` for intensity / reference maximum in (0, 12.5], (12.5, 37.5],
        (37.5, 75] and above 75 %).

    Returns
    -------
    pandas.DataFrame
        One row per (true_mode, band) present: ``n_flights``, ``n_alarmed``,
        ``alarm_rate`` (+ intervals), ``guilt_<mode>`` x 7 (mean over alarmed
        flights; NaN when none is alarmed), ``n_false_classification``,
        ``fcr`` (+ intervals).
    """
    config = ScoringConfig() if config is None else config
    true_mode = flights["true_mode"].to_numpy(dtype=object)
    single = np.isin(true_mode, MODE_IDS)
    row, unit, row_mode, row_band, n_units = mode_band_groups(
        true_mode, flights["band"].to_numpy(dtype=object), flights["unit_id"].to_numpy(),
        {m: i for i, m in enumerate(MODE_IDS)}, {b: i for i, b in enumerate(config.band_names)}, keep=single)
    alarmed = single & flights["alarm"].to_numpy(dtype=bool)
    wrong = alarmed & (flights["predicted"].to_numpy(dtype=object) != true_mode)
    shape = (len(row_mode), n_units)
    counts = {"n_flights": per_unit_counts(row, unit, shape), "n_alarmed": per_unit_counts(row, unit, shape, alarmed),
              "n_false_classification": per_unit_counts(row, unit, shape, wrong)}
    out = pooled_rates({"true_mode": row_mode, "band": row_band}, counts,
                       rates={"alarm_rate": ("n_alarmed", "n_flights"),
                              "fcr": ("n_false_classification", "n_alarmed")},
                       confidence=config.confidence, n_bootstrap=config.n_bootstrap,
                       random_state=config.random_state)
    for column, mean in _guilt_means(flights, row, alarmed, len(out)).items():
        out[column] = mean
    fixed = ["true_mode", "band", "n_flights", "n_alarmed", "alarm_rate", "alarm_rate_ci_low",
             "alarm_rate_ci_high", *GUILT_COLUMNS]
    return out[fixed + [c for c in out.columns if c not in fixed]]


def classification_table(flights: pd.DataFrame,
                         config: ScoringConfig | None = None) -> pd.DataFrame:
    """False classification rate per true mode and pooled (``"all"``).

    ``fcr`` = false classifications / alarmed single-fault flights (all bands):
    the paper's "proportion of false classification among all
    classifications". ``fcr_detectable`` restricts to detectable flights.

    Returns
    -------
    pandas.DataFrame
        Columns ``mode, n_alarmed, n_false_classification, fcr`` (+ intervals),
        ``n_alarmed_detectable, n_false_classification_detectable,
        fcr_detectable`` (+ intervals).
    """
    config = ScoringConfig() if config is None else config
    true_mode = flights["true_mode"].to_numpy(dtype=object)
    single = np.isin(true_mode, MODE_IDS)
    alarmed = single & flights["alarm"].to_numpy(dtype=bool)
    det = flights["detectable"].to_numpy(dtype=bool)
    wrong = alarmed & (flights["predicted"].to_numpy(dtype=object) != true_mode)
    unit, units = pd.factorize(flights["unit_id"], sort=False)  # -1: a missing unit id, left out as groupby does
    modes = modes_present(flights) + [ALL_MODES]
    counts = {c: [] for c in ("n_alarmed", "n_false_classification", "n_alarmed_detectable",
                              "n_false_classification_detectable")}
    one_row = np.zeros(len(unit), dtype=np.int64)
    for mode in modes:
        member = single if mode == ALL_MODES else (true_mode == mode)
        for column, mask in zip(counts, (alarmed, wrong, alarmed & det, wrong & det)):
            counts[column].append(per_unit_counts(one_row, unit, (1, len(units)), mask & member)[0])
    return pooled_rates(
        {"mode": np.array(modes, dtype=object)},
        {c: np.array(parts, dtype=np.int64).reshape(len(modes), len(units)) for c, parts in counts.items()},
        rates={"fcr": ("n_false_classification", "n_alarmed"),
               "fcr_detectable": ("n_false_classification_detectable", "n_alarmed_detectable")},
        confidence=config.confidence, n_bootstrap=config.n_bootstrap,
        random_state=config.random_state)


def confusion_matrix(flights: pd.DataFrame, config: ScoringConfig | None = None, *,
                     include_incipient: bool = False) -> pd.DataFrame:
    """Counts of true condition x predicted condition.

    Parameters
    ----------
    flights : pandas.DataFrame
        Output of :func:`fuelhm_bench.scoring.flight_table`.
    config : ScoringConfig or None, default=None
    include_incipient : bool, default=False
        Also count incipient (not yet detectable) faulty flights in the mode
        rows. By default the mode rows hold detectable flights only.

    Returns
    -------
    pandas.DataFrame
        Index ``true_condition``: ``"healthy"`` then the modes present;
        columns ``"no_alarm"``, the 7 mode ids, ``"tie"``. Multi-fault flights
        are not counted.
    """
    config = ScoringConfig() if config is None else config
    true_mode = flights["true_mode"].to_numpy(dtype=object)
    keep = true_mode == HEALTHY
    faulty_ok = np.isin(true_mode, MODE_IDS)
    if not include_incipient:
        faulty_ok &= flights["detectable"].to_numpy(dtype=bool)
    keep |= faulty_ok
    rows = [HEALTHY, *modes_present(flights[keep])]
    cols = [NO_ALARM, *MODE_IDS, TIE]
    row = _positions(true_mode[keep], rows)
    col = _positions(flights["predicted"].to_numpy(dtype=object)[keep], cols)
    counted = (row >= 0) & (col >= 0)  # crosstab leaves out a value outside the categories
    cells = np.bincount(row[counted] * len(cols) + col[counted], minlength=len(rows) * len(cols))
    return pd.DataFrame(cells.astype(np.int64).reshape(len(rows), len(cols)),
                        index=pd.Index(rows, name="true_condition"), columns=pd.Index(cols, name="predicted"))


def _positions(values: np.ndarray, categories: list[str]) -> np.ndarray:
    """Position of every value in ``categories`` (-1 when it is not one)."""
    codes, uniques = pd.factorize(values, sort=False)
    at = {c: i for i, c in enumerate(categories)}
    return np.append(np.array([at.get(u, -1) for u in uniques], dtype=np.int64), -1)[codes]
