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

import importlib

_HOMES = {  # public name -> its module: imported on first use (PEP 562), so that importing one
    # submodule (e.g. scoring.config, as the scenario schema does) does not import scipy.stats and matplotlib
    **dict.fromkeys(('INTERVAL_KPIS', 'kpi_intervals', 'scorecard_intervals'), "bootstrap"),
    **dict.fromkeys(('brier_score', 'guilt_calibration', 'plot_reliability', 'reliability_table'), "calibration"),
    **dict.fromkeys(('ScoringConfig',), "config"),
    **dict.fromkeys(('maintenance_cost', 'total_cost'), "cost"),
    **dict.fromkeys(('delay_summary', 'detection_delays'), "delay"),
    **dict.fromkeys(('ALL_MODES', 'METHOD_ALARM', 'detection_by_band', 'detection_table'), "detection"),
    **dict.fromkeys(('classification_table', 'confusion_matrix', 'diagnosis_table'), "diagnosis"),
    **dict.fromkeys(('to_latex', 'to_markdown', 'write_tables'), "export"),
    **dict.fromkeys(('plot_score_distributions', 'save_figure'), "figures"),
    **dict.fromkeys(('bootstrap_ratio_interval', 'rates_with_intervals', 'wilson_interval'), "intervals"),
    **dict.fromkeys(('null_decisions', 'perfect_decisions'), "reference"),
    **dict.fromkeys(('degradation_summary', 'drift_sweep_table', 'error_rate_changes', 'robustness', 'robustness_table'), "robustness"),
    **dict.fromkeys(('cd_diagram', 'critical_difference', 'friedman_test', 'mean_ranks', 'rank_matrix', 'wilcoxon_holm'), "ranking"),
    **dict.fromkeys(('HEALTHY', 'LABEL_COLUMNS', 'MULTIPLE', 'NO_ALARM', 'TIE', 'Run', 'flight_table'), "run"),
    **dict.fromkeys(('HEADLINE_KPIS', 'SCORECARD_TABLES', 'Scorecard', 'headline_kpis', 'score_run', 'undefined_kpis'),
                    "scorecard"),
    **dict.fromkeys(('summary_components', 'summary_score'), "summary"),
    **dict.fromkeys(('HealthyScoreModel', 'fit_healthy_model', 'threshold_table'), "thresholds"),
}

__all__ = [
    "INTERVAL_KPIS", "brier_score", "cd_diagram", "critical_difference", "friedman_test",
    "guilt_calibration", "kpi_intervals", "mean_ranks", "plot_reliability", "rank_matrix",
    "reliability_table", "scorecard_intervals", "wilcoxon_holm",
    "ALL_MODES", "HEADLINE_KPIS", "HEALTHY", "HealthyScoreModel", "LABEL_COLUMNS", "METHOD_ALARM",
    "MULTIPLE", "NO_ALARM", "Run", "SCORECARD_TABLES", "Scorecard", "ScoringConfig", "TIE", "bootstrap_ratio_interval",
    "classification_table", "confusion_matrix", "delay_summary", "detection_by_band",
    "detection_delays", "detection_table", "diagnosis_table", "fit_healthy_model",
    "flight_table", "headline_kpis", "maintenance_cost", "null_decisions", "perfect_decisions",
    "plot_score_distributions", "rates_with_intervals", "robustness", "robustness_table",
    "degradation_summary", "drift_sweep_table", "error_rate_changes",
    "save_figure", "score_run", "undefined_kpis", "summary_components", "summary_score", "threshold_table",
    "to_latex", "to_markdown", "total_cost", "wilson_interval", "write_tables",
]


def __getattr__(name: str):
    module = _HOMES.get(name)
    if module is None:
        raise AttributeError(f"module 'fuelhm_bench.scoring' has no attribute {name!r}")
    loaded = importlib.import_module(f"fuelhm_bench.scoring.{module}")
    for other, home in _HOMES.items():  # every name of that module, which also puts the function
        if home == module:              # robustness back over the submodule the import system bound
            globals()[other] = getattr(loaded, other)
    return globals()[name]


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
