"""Reference decisions built from the labels: the perfect and the null method.

They anchor the normalised score (NAB practice) and serve as behavioural test
fixtures. They are *not* methods (they read the labels) and must never be
entered in a results table as such.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from fuelhm_bench.methods.tables import DECISION_COLUMNS, GUILT_COLUMNS
from fuelhm_bench.scoring.run import INTENSITY_COLUMNS, UNKNOWN_ONSET_COLUMN

__all__ = ["null_decisions", "perfect_decisions"]


def perfect_decisions(labels: pd.DataFrame) -> pd.DataFrame:
    """Decisions of an oracle: alarm on every faulty flight, all guilt on the true mode.

    Parameters
    ----------
    labels : pandas.DataFrame
        Labels table.

    Returns
    -------
    pandas.DataFrame
        Decisions table: ``score`` = largest intensity (0 when healthy), ``alarm``
        = any intensity > 0, guilt shared equally among the active modes. A
        flight whose only fault is outside the seven modes (``onset_unknown``
        reached) is alarmed with score 1 and uniform guilt: no mode is named.
    """
    inten = labels[list(INTENSITY_COLUMNS)].to_numpy(dtype=float)
    active = inten > 0
    alarm = active.any(axis=1)
    guilt = np.where(alarm[:, None], active / np.maximum(active.sum(axis=1, keepdims=True), 1),
                     0.0)
    score = inten.max(axis=1)
    if UNKNOWN_ONSET_COLUMN in labels.columns:
        onset = labels[UNKNOWN_ONSET_COLUMN].to_numpy(dtype=float)
        unknown = (onset >= 0) & (labels["flight_index"].to_numpy() >= onset) & ~alarm
        guilt[unknown] = 1.0 / guilt.shape[1]
        score = np.where(unknown, 1.0, score)
        alarm = alarm | unknown
    return _frame(labels, score, alarm, guilt)


def null_decisions(labels: pd.DataFrame) -> pd.DataFrame:
    """Decisions of a method that never alarms: score 0, no guilt."""
    n = len(labels)
    return _frame(labels, np.zeros(n), np.zeros(n, dtype=bool), np.zeros((n, len(GUILT_COLUMNS))))


def _frame(labels: pd.DataFrame, score: np.ndarray, alarm: np.ndarray,
           guilt: np.ndarray) -> pd.DataFrame:
    out = {"unit_id": labels["unit_id"].to_numpy(),
           "flight_index": labels["flight_index"].to_numpy(dtype=np.int64),
           "score": score.astype(float), "alarm": alarm.astype(bool)}
    out.update({c: guilt[:, j] for j, c in enumerate(GUILT_COLUMNS)})
    return pd.DataFrame(out, columns=list(DECISION_COLUMNS))
