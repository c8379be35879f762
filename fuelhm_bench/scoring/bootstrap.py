"""Bootstrap confidence intervals of the headline KPIs, resampling units.

Flights of one unit share a unit and a degradation history, so they are not
independent: a unit bootstrap draws ``U`` of the run's ``U`` units with
replacement (a multinomial weight per unit) and recomputes each KPI from the
weighted per-unit counts; the interval is the percentile interval of the
resampled values. The point value is the KPI of the run itself, identical to
:func:`fuelhm_bench.scoring.headline_kpis`.

KPIs covered (definitions in docs/scoring.md):

* ``summary_score`` (normalised, null 0, perfect 100);
* ``fpr_standard_alarm``, ``fnr_standard_alarm``, ``balanced_accuracy_alarm``
  (the method's own alarms);
* ``fpr_standard_thr``, ``fnr_standard_thr``, ``balanced_accuracy_thr`` (the
  threshold ``mu + A sigma`` of the healthy-training scores at
  ``config.headline_a``; the threshold itself is held fixed);
* ``fcr`` (false classifications among alarmed single-fault flights).

Worked example: two units, unit 1 with 2 healthy flights of which 1 is alarmed,
unit 2 with 2 healthy flights, none alarmed: ``fpr = 1/4``; a resample drawing
unit 1 twice gives ``2/4``, unit 2 twice gives ``0/4``, one of each ``1/4``.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.scoring.run import HEALTHY, TIE, UNKNOWN
from fuelhm_bench.scoring.thresholds import HealthyScoreModel
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["INTERVAL_KPIS", "kpi_intervals", "scorecard_intervals"]

#: KPIs that :func:`kpi_intervals` gives intervals for.
INTERVAL_KPIS: tuple[str, ...] = (
    "summary_score", "fpr_standard_alarm", "fnr_standard_alarm", "balanced_accuracy_alarm",
    "fpr_standard_thr", "fnr_standard_thr", "balanced_accuracy_thr", "fcr")


def _unit_counts(flights: pd.DataFrame, threshold: float) -> tuple[np.ndarray, list[str]]:
    """Per-unit counts (units x columns) and the column names."""
    true_mode = flights["true_mode"].to_numpy()
    alarm = flights["alarm"].to_numpy(dtype=bool)
    thr = flights["score"].to_numpy(dtype=float) > threshold
    healthy = true_mode == HEALTHY
    det = flights["detectable"].to_numpy(dtype=bool)
    single = np.isin(true_mode, MODE_IDS)
    predicted = flights["predicted"].to_numpy()
    correct = (predicted == true_mode) | ((true_mode == UNKNOWN) & (predicted == TIE))
    cols = {"healthy": healthy, "fp_alarm": healthy & alarm, "fp_thr": healthy & thr,
            "det": det, "fn_alarm": det & ~alarm, "fn_thr": det & ~thr,
            "cls_alarmed": single & alarm, "cls_wrong": single & alarm & ~correct}
    for m in (*MODE_IDS, UNKNOWN):
        member = det & (true_mode == m)
        cols[f"n_{m}"] = member
        cols[f"tp_{m}"] = member & alarm
        cols[f"ok_{m}"] = member & alarm & correct
    frame = pd.DataFrame({k: v.astype(np.int64) for k, v in cols.items()})
    codes = pd.factorize(flights["unit_id"], use_na_sentinel=False)[0]
    summed = frame.groupby(codes, sort=True).sum()
    return summed.to_numpy(dtype=float), list(frame.columns)


def _kpis(c: dict[str, np.ndarray], w: float) -> dict[str, np.ndarray]:
    """KPIs from (weighted) count sums; each array has one entry per resample."""
    def ratio(num, den):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)

    out = {"fpr_standard_alarm": ratio(c["fp_alarm"], c["healthy"]),
           "fnr_standard_alarm": ratio(c["fn_alarm"], c["det"]),
           "fpr_standard_thr": ratio(c["fp_thr"], c["healthy"]),
           "fnr_standard_thr": ratio(c["fn_thr"], c["det"]),
           "fcr": ratio(c["cls_wrong"], c["cls_alarmed"])}
    for op in ("alarm", "thr"):
        out[f"balanced_accuracy_{op}"] = 1.0 - (out[f"fpr_standard_{op}"]
                                                + out[f"fnr_standard_{op}"]) / 2.0
    fpr = np.where(c["healthy"] > 0, ratio(c["fp_alarm"], c["healthy"]), 0.0)
    terms, present = [], []
    for m in (*MODE_IDS, UNKNOWN):
        n = c[f"n_{m}"]
        tpr = ratio(c[f"tp_{m}"], n)
        acc = np.where(c[f"tp_{m}"] > 0, ratio(c[f"ok_{m}"], c[f"tp_{m}"]), 0.0)
        j = tpr - fpr
        terms.append(np.where(j > 0, j * (w + (1 - w) * acc), j))
        present.append(n > 0)
    terms_a, present_a = np.array(terms), np.array(present)
    n_present = present_a.sum(axis=0)
    total = np.where(present_a, terms_a, 0.0).sum(axis=0)
    out["summary_score"] = np.where(n_present > 0, 100.0 * total / np.maximum(n_present, 1),
                                    np.nan)
    return out


def kpi_intervals(flights: pd.DataFrame, healthy_model: HealthyScoreModel,
                  config: ScoringConfig | None = None, *, n_resamples: int = 2000,
                  confidence: float = 0.95, random_state: int | np.random.Generator = 0
                  ) -> pd.DataFrame:
    """Unit-bootstrap percentile intervals of the headline KPIs of one run.

    Parameters
    ----------
    flights : pandas.DataFrame
        Per-flight table (:func:`fuelhm_bench.scoring.flight_table`).
    healthy_model : HealthyScoreModel
        Gaussian fit of the healthy-training scores (gives the ``*_thr`` threshold).
    config : ScoringConfig or None, default=None
        ``headline_a`` and ``summary_detection_weight`` are used.
    n_resamples : int, default=2000
        Bootstrap resamples (> 0).
    confidence : float, default=0.95
        Level in (0, 1).
    random_state : int or numpy.random.Generator, default=0
        Seed: the same seed gives the same intervals.

    Returns
    -------
    pandas.DataFrame
        One row per KPI of :data:`INTERVAL_KPIS`: ``kpi, value, ci_low, ci_high,
        n_units, n_resamples, confidence``. ``value`` is the run's own KPI;
        bounds are NaN when the KPI is undefined in every resample.

    Raises
    ------
    ParameterError
        For an invalid ``n_resamples`` or ``confidence``.

    Examples
    --------
    >>> import pandas as pd
    >>> from fuelhm_bench.scoring import fit_healthy_model
    >>> flights = pd.DataFrame({"unit_id": [1, 1, 2, 2], "flight_index": [0, 1, 0, 1],
    ...     "true_mode": ["healthy"] * 4, "detectable": [False] * 4, "score": [0.0] * 4,
    ...     "alarm": [True, False, False, False], "predicted": ["tie", "no_alarm", "no_alarm",
    ...     "no_alarm"]})
    >>> t = kpi_intervals(flights, fit_healthy_model([0.0, 1.0]))
    >>> t.set_index("kpi").loc["fpr_standard_alarm", ["value", "ci_low", "ci_high"]].tolist()
    [0.25, 0.0, 0.5]
    """
    config = ScoringConfig() if config is None else config
    owner = "kpi_intervals"
    if isinstance(n_resamples, bool) or not isinstance(n_resamples, (int, np.integer)) \
            or n_resamples < 1:
        raise ParameterError(f"The 'n_resamples' parameter of {owner} must be an int >= 1. "
                             f"Got {n_resamples!r} instead.")
    if isinstance(confidence, bool) or not isinstance(confidence, (int, float)) \
            or not 0 < confidence < 1:
        raise ParameterError(f"The 'confidence' parameter of {owner} must be a float in (0, 1). "
                             f"Got {confidence!r} instead.")
    rng = (random_state if isinstance(random_state, np.random.Generator)
           else np.random.default_rng(random_state))
    counts, cols = _unit_counts(flights, healthy_model.threshold(config.headline_a))
    n_units = counts.shape[0]
    w = config.summary_detection_weight
    point = _kpis({c: counts[:, j].sum(keepdims=True) for j, c in enumerate(cols)}, w)
    weights = rng.multinomial(n_units, np.full(n_units, 1.0 / n_units), size=n_resamples)
    sums = weights.astype(float) @ counts
    boot = _kpis({c: sums[:, j] for j, c in enumerate(cols)}, w)
    alpha = 1.0 - confidence
    rows = []
    for kpi in INTERVAL_KPIS:
        values = boot[kpi]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            low, high = (np.nanquantile(values, [alpha / 2, 1 - alpha / 2])
                         if np.isfinite(values).any() else (np.nan, np.nan))
        rows.append({"kpi": kpi, "value": float(point[kpi][0]), "ci_low": float(low),
                     "ci_high": float(high), "n_units": n_units, "n_resamples": int(n_resamples),
                     "confidence": float(confidence)})
    return pd.DataFrame(rows)


def scorecard_intervals(scorecard, **kwargs) -> pd.DataFrame:
    """:func:`kpi_intervals` of a :class:`~fuelhm_bench.scoring.Scorecard` (same keywords)."""
    return kpi_intervals(scorecard.flights, scorecard.healthy_model, scorecard.config, **kwargs)
