"""Robustness (paper Table III): how much a KPI survives a drift of nominal parameters.

The paper defines robustness as the "capacity of the monitoring system to be
still efficient when some parameters drift from their nominal values". We make
it a number by comparing two runs of the *same fitted method* (fitted once on
nominal healthy flights, so both runs carry the same healthy-training scores
and thus the same thresholds):

* the *nominal* run: evaluation fleet simulated with the nominal parameters;
* the *drifted* run: the same kind of fleet simulated with drifted nominal
  parameters (e.g. supply pressure, fluid temperature, hidden effects).

``robustness(nominal, drifted) = KPI(drifted) / KPI(nominal)`` for a KPI where
higher is better, by default the balanced detection accuracy at ``A = 2``,
``1 - (FPR_standard + FNR_standard) / 2`` over all flights. 1 means no loss,
0.9 a 10 % loss; values above 1 are possible (the drifted run happened to be
easier). The balanced accuracy is used because it does not depend on the
share of faulty flights, so a different fault mix cannot pass for a loss of
robustness. :func:`robustness_table` gives every headline KPI with its
difference ``drifted - nominal``.
"""

from __future__ import annotations

import math

import pandas as pd

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.scoring.run import Run
from fuelhm_bench.scoring.scorecard import HEADLINE_KPIS, Scorecard, headline_kpis, score_run

__all__ = ["robustness", "robustness_table"]


def _card(x: Run | Scorecard, config: ScoringConfig | None, what: str) -> Scorecard:
    if isinstance(x, Scorecard):
        return x
    if isinstance(x, Run):
        return score_run(x, config)
    raise ParameterError(f"The '{what}' parameter of robustness must be a Run or a Scorecard. "
                         f"Got {type(x).__name__} instead.")


def robustness_table(nominal: Run | Scorecard, drifted: Run | Scorecard, *,
                     config: ScoringConfig | None = None) -> pd.DataFrame:
    """Every headline KPI in the nominal and drifted runs.

    Parameters
    ----------
    nominal, drifted : Run or Scorecard
        Runs are scored with ``config``.
    config : ScoringConfig or None, default=None

    Returns
    -------
    pandas.DataFrame
        Columns ``kpi, nominal, drifted, delta`` (= drifted - nominal),
        ``ratio`` (= drifted / nominal, NaN when nominal is 0 or NaN),
        ``higher_is_better`` and ``worse`` (True when the drift degraded it, <NA> when
        either value is undefined).
    """
    a = headline_kpis(_card(nominal, config, "nominal"))
    b = headline_kpis(_card(drifted, config, "drifted"))
    rows = []
    for kpi, higher in HEADLINE_KPIS.items():
        delta = b[kpi] - a[kpi]
        ratio = b[kpi] / a[kpi] if a[kpi] and not math.isnan(a[kpi]) else math.nan
        worse = pd.NA if math.isnan(delta) else bool(delta < 0 if higher else delta > 0)
        rows.append({"kpi": kpi, "nominal": a[kpi], "drifted": b[kpi], "delta": delta,
                     "ratio": ratio, "higher_is_better": higher, "worse": worse})
    out = pd.DataFrame(rows)
    out["worse"] = out["worse"].astype("boolean")
    return out


def robustness(nominal: Run | Scorecard, drifted: Run | Scorecard, *,
               kpi: str = "balanced_accuracy_thr", config: ScoringConfig | None = None) -> float:
    """Robustness = KPI(drifted) / KPI(nominal) for a higher-is-better headline KPI.

    Parameters
    ----------
    nominal, drifted : Run or Scorecard
    kpi : str, default="balanced_accuracy_thr"
        A key of :data:`HEADLINE_KPIS` with higher-is-better (balanced accuracy at
        the headline ``A``, at the method's alarm, classification accuracy,
        detected event fraction, summary score).
    config : ScoringConfig or None, default=None

    Returns
    -------
    float
        NaN when the nominal KPI is 0 or undefined.

    Raises
    ------
    ParameterError
        For an unknown or lower-is-better KPI.
    """
    allowed = [k for k, higher in HEADLINE_KPIS.items() if higher]
    if kpi not in allowed:
        raise ParameterError(f"The 'kpi' parameter of robustness must be one of {allowed}. "
                             f"Got {kpi!r} instead.")
    table = robustness_table(nominal, drifted, config=config).set_index("kpi")
    return float(table.loc[kpi, "ratio"])
