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
from fuelhm_bench.scoring.detection import ALL_MODES, modes_present
from fuelhm_bench.scoring.intervals import rates_with_intervals
from fuelhm_bench.scoring.run import HEALTHY, NO_ALARM, TIE
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["classification_table", "confusion_matrix", "diagnosis_table"]


def _single_fault(flights: pd.DataFrame) -> pd.DataFrame:
    return flights[flights["true_mode"].isin(MODE_IDS)]


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
    sub = _single_fault(flights)
    alarmed = sub["alarm"].to_numpy(dtype=bool)
    wrong = alarmed & (sub["predicted"].to_numpy() != sub["true_mode"].to_numpy())
    band_order = {b: i for i, b in enumerate(config.band_names)}
    counts = pd.DataFrame({"true_mode": sub["true_mode"].to_numpy(),
                           "band": sub["band"].to_numpy(), "unit_id": sub["unit_id"].to_numpy(),
                           "n_flights": 1, "n_alarmed": alarmed.astype(np.int64),
                           "n_false_classification": wrong.astype(np.int64)})
    counts["_o"] = (counts["true_mode"].map({m: i for i, m in enumerate(MODE_IDS)}) * 100
                    + counts["band"].map(band_order))
    counts = counts.sort_values("_o", kind="stable").drop(columns="_o")
    per_unit = counts.groupby(["true_mode", "band", "unit_id"], sort=False).sum().reset_index()
    out = rates_with_intervals(per_unit, keys=["true_mode", "band"],
                               counts=["n_flights", "n_alarmed", "n_false_classification"],
                               rates={"alarm_rate": ("n_alarmed", "n_flights"),
                                      "fcr": ("n_false_classification", "n_alarmed")},
                               confidence=config.confidence, n_bootstrap=config.n_bootstrap,
                               random_state=config.random_state)
    guilt = sub.loc[alarmed, ["true_mode", "band", *GUILT_COLUMNS]]
    means = guilt.groupby(["true_mode", "band"], sort=False)[list(GUILT_COLUMNS)].mean()
    out = out.merge(means.reset_index(), on=["true_mode", "band"], how="left")
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
    true_mode = flights["true_mode"].to_numpy()
    single = np.isin(true_mode, MODE_IDS)
    alarmed = single & flights["alarm"].to_numpy(dtype=bool)
    det = flights["detectable"].to_numpy(dtype=bool)
    wrong = alarmed & (flights["predicted"].to_numpy() != true_mode)
    cols = ["n_alarmed", "n_false_classification", "n_alarmed_detectable",
            "n_false_classification_detectable"]
    parts = []
    for mode in modes_present(flights) + [ALL_MODES]:
        member = single if mode == ALL_MODES else (true_mode == mode)
        c = pd.DataFrame({"unit_id": flights["unit_id"].to_numpy(),
                          "n_alarmed": alarmed & member,
                          "n_false_classification": wrong & member,
                          "n_alarmed_detectable": alarmed & member & det,
                          "n_false_classification_detectable": wrong & member & det})
        c = c.groupby("unit_id", sort=False)[cols].sum().astype(np.int64).reset_index()
        c.insert(0, "mode", mode)
        parts.append(c)
    counts = pd.concat(parts, ignore_index=True)
    return rates_with_intervals(
        counts, keys=["mode"], counts=cols,
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
    keep = flights["true_mode"].to_numpy() == HEALTHY
    faulty_ok = flights["true_mode"].isin(MODE_IDS).to_numpy().copy()
    if not include_incipient:
        faulty_ok &= flights["detectable"].to_numpy(dtype=bool)
    sub = flights[keep | faulty_ok]
    rows = [HEALTHY, *modes_present(sub)]
    cols = [NO_ALARM, *MODE_IDS, TIE]
    table = pd.crosstab(pd.Categorical(sub["true_mode"], categories=rows),
                        pd.Categorical(sub["predicted"], categories=cols), dropna=False)
    table.index = pd.Index(rows, name="true_condition")
    table.columns = pd.Index(cols, name="predicted")
    return table.astype(np.int64)
