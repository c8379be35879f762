"""Robustness (paper Table III): how much a KPI survives a drift of nominal parameters.

The paper defines robustness as the "capacity of the monitoring system to be
still efficient when some parameters drift from their nominal values". We make
it a number by comparing two runs of the *same fitted method* (fitted once on
nominal healthy flights, so both runs carry the same healthy-training scores
and thus the same thresholds):

* the *nominal* run: evaluation fleet simulated with the nominal parameters;
* the *drifted* run: the same kind of fleet simulated with drifted nominal
  parameters (e.g. supply pressure, fluid temperature, hidden effects).

The primary report is the change of the *two error rates separately*
(:func:`error_rate_changes`, and over a sweep :func:`drift_sweep_table`): a
drift that raises the false-positive rate and lowers the false-negative rate
(a method alarming more often) can leave a balanced accuracy unchanged, and a
single ratio cannot tell a method that resists drift from one that happens to
alarm less. :func:`degradation_summary` turns a sweep (one parameter at a time,
several magnitudes) into the smallest drift at which the performance degrades
by a stated amount.

The ratio ``robustness(nominal, drifted) = KPI(drifted) / KPI(nominal)`` for a KPI where
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

__all__ = ["degradation_summary", "drift_sweep_table", "error_rate_changes", "robustness", "robustness_table"]


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


def error_rate_changes(nominal: Run | Scorecard, drifted: Run | Scorecard, *,
                       config: ScoringConfig | None = None) -> dict[str, float]:
    """False-positive and false-negative rates of both runs at the headline ``A``, and their changes.

    Parameters
    ----------
    nominal, drifted : Run or Scorecard
    config : ScoringConfig or None, default=None

    Returns
    -------
    dict
        ``fpr_nominal``, ``fpr_drifted``, ``delta_fpr`` (= drifted - nominal; positive: more false
        alarms), ``fnr_nominal``, ``fnr_drifted``, ``delta_fnr`` (positive: more missed faulty
        flights), ``balanced_accuracy_nominal``, ``balanced_accuracy_drifted``,
        ``delta_balanced_accuracy``. Standard definitions of docs/scoring.md, over all flights.
    """
    a = headline_kpis(_card(nominal, config, "nominal"))
    b = headline_kpis(_card(drifted, config, "drifted"))
    out = {}
    for short, key in (("fpr", "fpr_standard_thr"), ("fnr", "fnr_standard_thr"),
                       ("balanced_accuracy", "balanced_accuracy_thr")):
        out[f"{short}_nominal"] = float(a[key])
        out[f"{short}_drifted"] = float(b[key])
        out[f"delta_{short}"] = float(b[key] - a[key])
    return out


def drift_sweep_table(nominal: Run | Scorecard, drifted, *, config: ScoringConfig | None = None) -> pd.DataFrame:
    """Error-rate changes of a drift sweep: one row per (parameter, magnitude).

    Parameters
    ----------
    nominal : Run or Scorecard
        The run without drift (same method, same fleet seeds).
    drifted : mapping of (str, float) to Run or Scorecard
        ``{(parameter, magnitude): run}``: one drifted run per parameter path and magnitude
        (relative change, or absolute in SI units, as the sweep declared).
    config : ScoringConfig or None, default=None

    Returns
    -------
    pandas.DataFrame
        Columns ``parameter``, ``magnitude`` and the keys of :func:`error_rate_changes`, sorted
        by parameter then ``abs(magnitude)``.

    Raises
    ------
    ParameterError
        ``drifted`` is not a non-empty mapping keyed by (parameter, magnitude).
    """
    if not hasattr(drifted, "items") or not drifted:
        raise ParameterError("The 'drifted' parameter of drift_sweep_table must be a non-empty mapping "
                             f"{{(parameter, magnitude): Run}}. Got {type(drifted).__name__} instead.")
    base = _card(nominal, config, "nominal")
    rows = []
    for key, run in drifted.items():
        if not (isinstance(key, tuple) and len(key) == 2 and isinstance(key[0], str)):
            raise ParameterError("The keys of the 'drifted' parameter of drift_sweep_table must be "
                                 f"(parameter, magnitude) pairs. Got {key!r} instead.")
        rows.append({"parameter": key[0], "magnitude": float(key[1]),
                     **error_rate_changes(base, _card(run, config, "drifted"))})
    out = pd.DataFrame(rows)
    out["_abs"] = out["magnitude"].abs()
    return out.sort_values(["parameter", "_abs", "magnitude"]).drop(columns="_abs").reset_index(drop=True)


def degradation_summary(sweep: pd.DataFrame, *, tolerance: float = 0.05) -> pd.DataFrame:
    """At what drift a method's performance degrades by ``tolerance``, per parameter.

    A drift *degrades* the method when its false-positive rate or its false-negative rate rises
    by more than ``tolerance`` (absolute, e.g. 0.05 = 5 percentage points) over the nominal run.

    Parameters
    ----------
    sweep : pandas.DataFrame
        :func:`drift_sweep_table` output.
    tolerance : float, default=0.05
        In (0, 1).

    Returns
    -------
    pandas.DataFrame
        One row per parameter: ``parameter``, ``tolerance``, ``degrades_at`` (the smallest
        ``abs(magnitude)`` swept at which either rate rose by more than ``tolerance``, with its
        sign; NaN when none did), ``by`` (``"fpr"``, ``"fnr"`` or ``"fpr+fnr"``), the largest
        ``max_delta_fpr`` and ``max_delta_fnr`` over the sweep, ``swept`` (the magnitudes) and
        ``summary``, a sentence.

    Examples
    --------
    >>> import pandas as pd
    >>> sweep = pd.DataFrame({"parameter": ["p"] * 3, "magnitude": [0.05, 0.1, 0.2],
    ...                       "delta_fpr": [0.01, 0.08, 0.3], "delta_fnr": [0.0, 0.0, -0.02]})
    >>> degradation_summary(sweep)["summary"].iloc[0]
    'p: FPR rises by more than 5 points at a drift of 0.1 (swept 0.05, 0.1, 0.2)'
    """
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not 0.0 < tolerance < 1.0:
        raise ParameterError(f"The 'tolerance' parameter of degradation_summary must be a float in (0, 1). "
                             f"Got {tolerance!r} instead.")
    missing = [c for c in ("parameter", "magnitude", "delta_fpr", "delta_fnr") if c not in getattr(sweep, "columns", ())]
    if missing:
        raise ParameterError(f"The 'sweep' parameter of degradation_summary must be a drift_sweep_table; "
                             f"it misses column(s) {missing}.")
    rows = []
    for parameter, part in sweep.groupby("parameter", sort=True):
        part = part.assign(_abs=part["magnitude"].abs()).sort_values(["_abs", "magnitude"])
        fp = part["delta_fpr"] > tolerance
        fn = part["delta_fnr"] > tolerance
        hit = part[fp | fn]
        swept = ", ".join(f"{m:g}" for m in part["magnitude"])
        points = f"{100 * tolerance:g} points"
        if hit.empty:
            at, by = math.nan, ""
            text = f"{parameter}: neither FPR nor FNR rises by more than {points} up to the largest drift swept ({swept})"
        else:
            first = hit.index[0]
            at = float(part.loc[first, "magnitude"])
            by = "+".join(name for name, flag in (("fpr", fp[first]), ("fnr", fn[first])) if flag)
            what = {"fpr": "FPR rises", "fnr": "FNR rises", "fpr+fnr": "FPR and FNR rise"}[by]
            text = f"{parameter}: {what} by more than {points} at a drift of {at:g} (swept {swept})"
        rows.append({"parameter": parameter, "tolerance": float(tolerance), "degrades_at": at, "by": by,
                     "max_delta_fpr": float(part["delta_fpr"].max()), "max_delta_fnr": float(part["delta_fnr"].max()),
                     "swept": swept, "summary": text})
    return pd.DataFrame(rows)
