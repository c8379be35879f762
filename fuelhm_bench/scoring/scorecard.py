"""Score a run: every table of the benchmark report in one frozen object."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from fuelhm_bench.errors import UnknownNameError
from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.scoring.delay import delay_summary, detection_delays
from fuelhm_bench.scoring.detection import (ALL_MODES, METHOD_ALARM, UNDEFINED_RATES, detection_by_band,
                                            detection_table)
from fuelhm_bench.scoring.diagnosis import (classification_table, confusion_matrix,
                                            diagnosis_table)
from fuelhm_bench.scoring.run import Run, flight_table
from fuelhm_bench.scoring.summary import score_of_components, summary_components
from fuelhm_bench.scoring.thresholds import HealthyScoreModel, fit_healthy_model, threshold_table

__all__ = ["HEADLINE_KPIS", "SCORECARD_TABLES", "Scorecard", "headline_kpis", "score_run", "undefined_kpis"]

#: Names of the tables of :meth:`Scorecard.tables` (files ``<name>.csv/.md/.tex`` of ``write_tables``).
SCORECARD_TABLES: tuple[str, ...] = (
    "thresholds", "table_v_detection", "detection_by_band", "table_vi_diagnosis", "classification", "confusion",
    "delays", "delay_summary", "summary_components", "headline",
)

#: Headline KPIs: name -> True when higher is better.
HEADLINE_KPIS: dict[str, bool] = {
    "fpr_standard_thr": False, "fnr_standard_thr": False,
    "fpr_paper_def_thr": False, "fnr_paper_def_thr": False, "balanced_accuracy_thr": True,
    "fpr_standard_alarm": False, "fnr_standard_alarm": False, "balanced_accuracy_alarm": True,
    "fcr": False, "classification_accuracy": True, "detected_event_fraction": True,
    "delay_censored_mean": False, "delay_censored_median": False, "summary_score": True,
}


@dataclass(frozen=True, eq=False)
class Scorecard:
    """All the result tables of one run (see docs/scoring.md for every column).

    Attributes
    ----------
    name : str
        Run name.
    config : ScoringConfig
    healthy_model : HealthyScoreModel
        Gaussian fit of the healthy-training scores.
    thresholds : pandas.DataFrame
        ``Thr = mu + A sigma`` per ``A``.
    flights : pandas.DataFrame
        Per-flight table (:func:`flight_table`).
    detection : pandas.DataFrame
        Table V (:func:`detection_table`).
    detection_by_band : pandas.DataFrame
    diagnosis : pandas.DataFrame
        Table VI (:func:`diagnosis_table`).
    classification : pandas.DataFrame
        False classification rate (:func:`classification_table`).
    confusion : pandas.DataFrame
        Confusion matrix (:func:`confusion_matrix`).
    delays : pandas.DataFrame
        Per-event delays (:func:`detection_delays`).
    delay_summary : pandas.DataFrame
    summary_components : pandas.DataFrame
    summary_score : float
        Normalised summary score (null 0, perfect 100).
    notes : tuple of str
        Caveats of this run (undefined rates, missing populations).
    """

    name: str
    config: ScoringConfig
    healthy_model: HealthyScoreModel
    thresholds: pd.DataFrame
    flights: pd.DataFrame
    detection: pd.DataFrame
    detection_by_band: pd.DataFrame
    diagnosis: pd.DataFrame
    classification: pd.DataFrame
    confusion: pd.DataFrame
    delays: pd.DataFrame
    delay_summary: pd.DataFrame
    summary_components: pd.DataFrame
    summary_score: float
    notes: tuple[str, ...]

    def detection_row(self, operating_point: str, mode: str = ALL_MODES) -> pd.Series:
        """The Table V row of an operating point (``"thr(A=2)"``, ``"method_alarm"``) and mode."""
        t = self.detection
        rows = t[(t["operating_point"] == operating_point) & (t["mode"] == mode)]
        if len(rows) != 1:
            raise UnknownNameError(f"The 'operating_point' and 'mode' parameters of "
                                   f"detection_row must name a row of the detection table. Got "
                                   f"{operating_point!r} and {mode!r} instead.")
        return rows.iloc[0]

    def tables(self) -> dict[str, pd.DataFrame]:
        """Every table by file-friendly name (:data:`SCORECARD_TABLES`, for :func:`write_tables`)."""
        return dict(zip(SCORECARD_TABLES, (
            self.thresholds, self.detection, self.detection_by_band, self.diagnosis, self.classification,
            self.confusion, self.delays, self.delay_summary, self.summary_components,
            headline_kpis(self).rename("value").rename_axis("kpi").reset_index())))


def headline_kpis(scorecard: Scorecard) -> pd.Series:
    """The headline KPIs of a run (keys of :data:`HEADLINE_KPIS`).

    ``*_thr`` come from the ``"all"`` row at ``A = config.headline_a``;
    ``*_alarm`` from the ``"all"`` row at the method's own alarm; ``fcr`` from
    the ``"all"`` row of the classification table; the detected event fraction
    and the censored delays (missed events count as their observed length,
    see :mod:`fuelhm_bench.scoring.delay`) from the ``"all"`` row of the delay
    summary.
    """
    cfg = scorecard.config
    thr = scorecard.detection_row(cfg.operating_point_name(cfg.headline_a))
    alarm = scorecard.detection_row(METHOD_ALARM)
    cls = scorecard.classification.set_index("mode").loc[ALL_MODES]
    ds = scorecard.delay_summary.set_index("mode")
    delay = ds.loc[ALL_MODES] if ALL_MODES in ds.index else None
    values = {
        "fpr_standard_thr": thr["fpr_standard"], "fnr_standard_thr": thr["fnr_standard"],
        "fpr_paper_def_thr": thr["fpr_paper_def"], "fnr_paper_def_thr": thr["fnr_paper_def"],
        "balanced_accuracy_thr": thr["balanced_accuracy"],
        "fpr_standard_alarm": alarm["fpr_standard"], "fnr_standard_alarm": alarm["fnr_standard"],
        "balanced_accuracy_alarm": alarm["balanced_accuracy"],
        "fcr": cls["fcr"], "classification_accuracy": 1.0 - cls["fcr"],
        "detected_event_fraction": np.nan if delay is None else delay["detected_fraction"],
        "delay_censored_mean": np.nan if delay is None
        else delay["delay_from_onset_censored_mean"],
        "delay_censored_median": np.nan if delay is None
        else delay["delay_from_onset_censored_median"],
        "summary_score": scorecard.summary_score,
    }
    return pd.Series({k: float(values[k]) for k in HEADLINE_KPIS}, dtype=float)


#: Why the summary score is undefined (NaN): it averages over the faulty flights.
NO_FAULT = "no scored flight is faulty (a scenario without a degradation that occurs measures false alarms only)"


def _rate_reason(scorecard: Scorecard, rate: str, operating_point: str) -> str:
    """Why ``rate`` (or ``balanced_accuracy``) of the ``"all"`` row at ``operating_point`` is undefined."""
    row = scorecard.detection_row(operating_point)
    rates = ("fpr_standard", "fnr_standard") if rate == "balanced_accuracy" else (rate,)
    why = "; ".join(UNDEFINED_RATES[r] for r in rates if r in UNDEFINED_RATES and row[r] != row[r])
    if operating_point == METHOD_ALARM:
        return f"{why} among the method's alarms"
    model = scorecard.healthy_model
    where = f"{why} at A = {row['a']:g} (threshold mu + A sigma = {row['threshold']:.4g})"
    if model.sigma == 0:
        where += (f"; the {model.n} calibration scores are all equal (sigma = 0), so every threshold is their "
                  f"value mu = {model.mu:.4g}")
    return where


def undefined_kpis(scorecard: Scorecard) -> dict[str, str]:
    """Why each undefined (NaN) headline KPI of a run is undefined.

    Parameters
    ----------
    scorecard : Scorecard

    Returns
    -------
    dict of str to str
        ``{kpi: reason}`` for the NaN values of :func:`headline_kpis`, e.g.
        ``{"fpr_paper_def_thr": "no detection: FP + FD = 0 at A = 2 (threshold ...)"}``;
        empty when every KPI is defined.
    """
    cfg = scorecard.config
    reasons = {}
    for kpi, value in headline_kpis(scorecard).items():
        if value == value:
            continue
        stem, _, point = kpi.rpartition("_")
        if point in ("thr", "alarm") and stem:
            op = cfg.operating_point_name(cfg.headline_a) if point == "thr" else METHOD_ALARM
            reasons[kpi] = _rate_reason(scorecard, stem, op)
        elif kpi in ("fcr", "classification_accuracy"):
            reasons[kpi] = "no flight with a single fault is alarmed, so no diagnosis is scored"
        elif kpi == "summary_score":
            reasons[kpi] = NO_FAULT
        else:  # the detected event fraction and the delays
            reasons[kpi] = "no degradation event among the scored flights"
    return reasons


def score_run(run: Run, config: ScoringConfig | None = None) -> Scorecard:
    """Compute every table of the benchmark report for one run.

    Parameters
    ----------
    run : Run
        Labels, decisions and the healthy-training scores.
    config : ScoringConfig or None, default=None
        None uses the defaults.

    Returns
    -------
    Scorecard

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> from fuelhm_bench.scoring import Run, perfect_decisions, score_run
    >>> from fuelhm_bench.taxonomy import MODE_IDS
    >>> labels = pd.DataFrame({"unit_id": [1, 1, 1], "flight_index": [0, 1, 2],
    ...     **{f"intensity_{m}": [0.0, 0.5, 1.0] if m == "backlash" else 0.0 for m in MODE_IDS},
    ...     **{f"max_intensity_{m}": 1.0 if m == "backlash" else 0.0 for m in MODE_IDS},
    ...     **{f"onset_{m}": 1 if m == "backlash" else -1 for m in MODE_IDS}})
    >>> card = score_run(Run(labels, perfect_decisions(labels), healthy_scores=[0.0, 0.1]))
    >>> card.summary_score
    100.0
    """
    config = ScoringConfig() if config is None else config
    model = fit_healthy_model(run.healthy_scores)
    flights = flight_table(run, config)
    detection = detection_table(flights, model, config)
    delays = detection_delays(flights, config)
    notes = []
    if not (flights["true_mode"] == "healthy").any():
        notes.append("no healthy flight in the run: false positive rates are undefined (NaN)")
    if not flights["detectable"].any():
        notes.append("no detectable faulty flight in the run: false negative rates are undefined")
    if (flights["true_mode"] == "multiple").any():
        notes.append("flights with several active degradations are counted only in the 'all' "
                     "rows of the detection table and in the delays")
    notes.extend(sorted({n for n in detection["note"] if n}))
    classification = classification_table(flights, config)
    if classification["fcr"].isna().any():
        notes.append("fcr undefined (NaN) where no single-fault flight is alarmed")
    components = summary_components(flights, config)
    return Scorecard(
        name=run.name, config=config, healthy_model=model,
        thresholds=threshold_table(model, config.a_values), flights=flights,
        detection=detection, detection_by_band=detection_by_band(flights, model, config),
        diagnosis=diagnosis_table(flights, config),
        classification=classification,
        confusion=confusion_matrix(flights, config), delays=delays,
        delay_summary=delay_summary(delays, config),
        summary_components=components, summary_score=score_of_components(components), notes=tuple(notes))
