"""A normalised summary score (NAB practice): null method = 0, perfect method = 100.

At the method's own operating point (its ``alarm``), for every mode ``m``
with at least one detectable single-fault flight (``"unknown"``, a fault
outside the seven modes, counts as one more mode, whose diagnosis is right
when the method names no single mode: a tie of the largest guilt):

* ``TPR_m`` = alarmed / detectable flights of mode ``m``;
* ``FPR``   = alarmed / healthy flights (shared by all modes; taken as 0, with
  a note, when the run has no healthy flight);
* ``ACC_m`` = correctly classified / alarmed detectable flights of mode ``m``
  (unique largest guilt on the true mode; 0 when none is alarmed);
* ``J_m = TPR_m - FPR`` (Youden's J: 0 for any method that alarms at random,
  whatever its alarm rate);
* ``S_m = J_m * (w + (1 - w) * ACC_m)`` when ``J_m > 0``, else ``S_m = J_m``,
  with ``w = summary_detection_weight`` (default 0.5: a perfect detector with
  useless diagnosis gets 50).

``summary_score = 100 * mean_m S_m`` (modes weigh equally, however many flights
they have). It lies in [-100, 100]: never alarming gives 0, alarming on exactly
the faulty flights with the right mode gives 100, and alarming more on healthy
flights than on faulty ones gives a negative score. Timeliness is not part of
it: see the delay tables.
"""

from __future__ import annotations

import pandas as pd

from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.scoring.run import HEALTHY, TIE, UNKNOWN
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["score_of_components", "summary_components", "summary_score"]


def summary_components(flights: pd.DataFrame,
                       config: ScoringConfig | None = None) -> pd.DataFrame:
    """Per-mode terms of the normalised summary score.

    Parameters
    ----------
    flights : pandas.DataFrame
        Output of :func:`fuelhm_bench.scoring.flight_table`.
    config : ScoringConfig or None, default=None

    Returns
    -------
    pandas.DataFrame
        Columns ``mode, n_detectable, tpr, fpr, youden_j, accuracy, term`` (one
        row per mode with detectable flights; ``term`` is ``S_m``).
    """
    config = ScoringConfig() if config is None else config
    w = config.summary_detection_weight
    true_mode = flights["true_mode"].to_numpy()
    alarm = flights["alarm"].to_numpy(dtype=bool)
    healthy = true_mode == HEALTHY
    fpr = float(alarm[healthy].mean()) if healthy.any() else 0.0
    correct = alarm & (flights["predicted"].to_numpy() == true_mode)
    det = flights["detectable"].to_numpy(dtype=bool)
    rows = []
    # A fault outside the seven modes is diagnosed right only by naming no single mode (a tie, e.g.
    # uniform guilt): naming one of the seven is wrong, so a library-only classifier gets no credit.
    correct = correct | (alarm & (true_mode == UNKNOWN) & (flights["predicted"].to_numpy() == TIE))
    for mode in (*MODE_IDS, UNKNOWN):
        member = det & (true_mode == mode)
        n = int(member.sum())
        if n == 0:
            continue
        n_alarmed = int((alarm & member).sum())
        tpr = n_alarmed / n
        acc = float((correct & member).sum() / n_alarmed) if n_alarmed else 0.0
        j = tpr - fpr
        term = j * (w + (1 - w) * acc) if j > 0 else j
        rows.append({"mode": mode, "n_detectable": n, "tpr": tpr, "fpr": fpr, "youden_j": j,
                     "accuracy": acc, "term": term})
    return pd.DataFrame(rows, columns=["mode", "n_detectable", "tpr", "fpr", "youden_j",
                                       "accuracy", "term"])


def summary_score(flights: pd.DataFrame, config: ScoringConfig | None = None) -> float:
    """Normalised summary score in [-100, 100] (null = 0, perfect = 100; NaN without faults).

    Examples
    --------
    See docs/scoring.md, section "Normalised summary score", for a worked value.
    """
    return score_of_components(summary_components(flights, config))


def score_of_components(components: pd.DataFrame) -> float:
    """:func:`summary_score` from the table of :func:`summary_components` (NaN when it has no row)."""
    return float(100.0 * components["term"].mean()) if len(components) else float("nan")
