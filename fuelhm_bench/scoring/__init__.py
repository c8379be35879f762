"""The scorer: from labels + decisions (+ healthy-training scores) to the paper's tables.

Public API
----------
Run, ScoringConfig, score_run, Scorecard, headline_kpis
    Score one run.
flight_table, detection_table, detection_by_band, diagnosis_table,
classification_table, confusion_matrix, detection_delays, delay_summary,
summary_components, summary_score
    The individual tables (Table V, Table VI, FCR, confusion, delays, summary).
fit_healthy_model, HealthyScoreModel, threshold_table
    Thresholds ``mu + A sigma`` from healthy-training scores only (paper eq. 10).
wilson_interval, bootstrap_ratio_interval, rates_with_intervals
    Confidence intervals.
error_rate_changes, drift_sweep_table, degradation_summary
    Robustness: FPR and FNR changes under drift, over a sweep, and the drift at which a method
    degrades by a stated amount (the sweep itself: :mod:`fuelhm_bench.benchmark.drift_sweep`).
kpi_intervals, scorecard_intervals (scoring.bootstrap)
    Unit-bootstrap intervals of the headline KPIs and the summary score.
mean_ranks, friedman_test, critical_difference, wilcoxon_holm, cd_diagram (scoring.ranking)
    Aggregate over scenarios and seeds (Demsar 2006).
brier_score, reliability_table, guilt_calibration, plot_reliability (scoring.calibration)
    Calibration of guilt probabilities.
robustness, robustness_table
    Nominal vs drifted runs: every headline KPI, and one KPI's ratio.
perfect_decisions, null_decisions
    Reference decisions (oracle and never-alarm).
maintenance_cost, total_cost
    Cost of the decisions under a scenario's cost model, replayed with maintenance.
to_markdown, to_latex, write_tables, plot_score_distributions, save_figure
    Export.

See docs/scoring.md for every definition with worked examples.
"""

from fuelhm_bench.scoring.bootstrap import INTERVAL_KPIS, kpi_intervals, scorecard_intervals
from fuelhm_bench.scoring.calibration import (brier_score, guilt_calibration, plot_reliability,
                                              reliability_table)
from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.scoring.cost import maintenance_cost, total_cost
from fuelhm_bench.scoring.delay import delay_summary, detection_delays
from fuelhm_bench.scoring.detection import (ALL_MODES, METHOD_ALARM, detection_by_band,
                                            detection_table)
from fuelhm_bench.scoring.diagnosis import (classification_table, confusion_matrix,
                                            diagnosis_table)
from fuelhm_bench.scoring.export import to_latex, to_markdown, write_tables
from fuelhm_bench.scoring.figures import plot_score_distributions, save_figure
from fuelhm_bench.scoring.intervals import (bootstrap_ratio_interval, rates_with_intervals,
                                            wilson_interval)
from fuelhm_bench.scoring.reference import null_decisions, perfect_decisions
from fuelhm_bench.scoring.robustness import (
    degradation_summary,
    drift_sweep_table,
    error_rate_changes,
    robustness,
    robustness_table,
)
from fuelhm_bench.scoring.ranking import (cd_diagram, critical_difference, friedman_test,
                                          mean_ranks, rank_matrix, wilcoxon_holm)
from fuelhm_bench.scoring.run import (HEALTHY, LABEL_COLUMNS, MULTIPLE, NO_ALARM, TIE, Run,
                                      flight_table)
from fuelhm_bench.scoring.scorecard import HEADLINE_KPIS, Scorecard, headline_kpis, score_run
from fuelhm_bench.scoring.summary import summary_components, summary_score
from fuelhm_bench.scoring.thresholds import HealthyScoreModel, fit_healthy_model, threshold_table

__all__ = [
    "INTERVAL_KPIS", "brier_score", "cd_diagram", "critical_difference", "friedman_test",
    "guilt_calibration", "kpi_intervals", "mean_ranks", "plot_reliability", "rank_matrix",
    "reliability_table", "scorecard_intervals", "wilcoxon_holm",
    "ALL_MODES", "HEADLINE_KPIS", "HEALTHY", "HealthyScoreModel", "LABEL_COLUMNS", "METHOD_ALARM",
    "MULTIPLE", "NO_ALARM", "Run", "Scorecard", "ScoringConfig", "TIE", "bootstrap_ratio_interval",
    "classification_table", "confusion_matrix", "delay_summary", "detection_by_band",
    "detection_delays", "detection_table", "diagnosis_table", "fit_healthy_model",
    "flight_table", "headline_kpis", "maintenance_cost", "null_decisions", "perfect_decisions",
    "plot_score_distributions", "rates_with_intervals", "robustness", "robustness_table",
    "degradation_summary", "drift_sweep_table", "error_rate_changes",
    "save_figure", "score_run", "summary_components", "summary_score", "threshold_table",
    "to_latex", "to_markdown", "total_cost", "wilson_interval", "write_tables",
]
