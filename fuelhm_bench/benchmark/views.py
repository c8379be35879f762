"""Views of the results store: ``leaderboard.csv`` / ``leaderboard.md``, per-scenario and per-method reports.

``leaderboard.md`` opens with the aggregate over scenarios and seeds (mean rank per entry, the Friedman
test, the Nemenyi critical difference and Wilcoxon-Holm against the best entry:
:func:`fuelhm_bench.scoring.ranking.aggregate_ranking`), also written as ``aggregate.csv`` (one row per
entry; the test statistics repeated on every row) and ``aggregate_pairs.csv`` (every Wilcoxon-Holm pair).

Every file here is generated from :class:`~fuelhm_bench.benchmark.store.ResultStore`
rows and tables, never from a run in memory, so a resumed run, a distributed
run and a local run write the same views. Per-method folders are named
``<method>-<hash of method and parameters>`` so two settings of one class never
share a folder; a folder is regenerated only when its stored key changed.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pandas as pd

__all__ = ["aggregate_view", "board_table", "method_folder", "slug", "write_views"]

_MD_COLUMNS = ("scenario", "seed", "method", "params", "status", "summary_score", "summary_score_ci_low",
               "summary_score_ci_high", "fpr_standard_thr", "fnr_standard_thr", "fcr", "brier",
               "delay_censored_mean", "cost_kusd", "robustness", "robustness_delta_fpr", "robustness_delta_fnr",
               "fit_seconds", "decide_seconds", "message")

#: Files of a method's report linked from the page (label -> file name in its folder).
_PAGE_LINKS = (("report", "result.json"), ("detection", "table_v_detection.md"),
               ("scores", "score_distributions.png"), ("reliability", "reliability.png"),
               ("intervals", "headline_intervals.csv"), ("log", "method.log"))


def slug(text: str) -> str:
    """A file-name-safe version of a method entry point."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")[:80]


def method_folder(out, task) -> Path:
    """Folder of a task's per-method report: ``<out>/<scenario>-seed<seed>/<method>-<short hash>``."""
    return Path(out) / f"{task.scenario_id}-seed{task.seed}" / f"{slug(task.method)}-{task.short}"


def board_table(store, tasks) -> pd.DataFrame:
    """One row per task found in the store: identity, parameters (JSON), status, message, KPIs, timings."""
    records = store.records([t.key for t in tasks])
    by_key = {r["key"]: r for r in records.to_dict("records")}
    rows = []
    for t in tasks:
        r = by_key.get(t.key)
        if r is None:
            continue
        rows.append({"scenario": t.scenario_id, "seed": t.seed, "fidelity": r["fidelity"], "method": t.method,
                     "params": json.dumps(r["params"], sort_keys=True), "status": r["status"],
                     "message": r["message"], **(r["kpis"] or {}), "fit_seconds": r["fit_seconds"],
                     "decide_seconds": r["decide_seconds"], "seconds": r["seconds"], "key": t.key[:16],
                     "folder": str(method_folder(".", t)), "method_params": r["method_params"]})
    board = pd.DataFrame(rows)
    if "summary_score" in board:
        board = board.sort_values(["scenario", "seed", "summary_score"], ascending=[True, True, False],
                                  na_position="last", kind="stable").reset_index(drop=True)
    return board


def aggregate_view(board: pd.DataFrame, *, value: str = "summary_score", alpha: float = 0.05):
    """The aggregate of a board (:func:`board_table`) and its CSV form.

    Returns
    -------
    aggregate : Aggregate
        :func:`fuelhm_bench.scoring.ranking.aggregate_ranking` of the board's ok entries.
    csv : pandas.DataFrame
        ``aggregate.table`` plus ``friedman_statistic``, ``friedman_pvalue``, ``critical_difference``,
        ``n_methods``, ``alpha`` on every row.
    """
    from fuelhm_bench.scoring.ranking import aggregate_ranking

    frame = board if value in board.columns else board.assign(**{value: float("nan")})
    if "method" not in frame.columns:
        frame = frame.assign(method=pd.Series(dtype=object))
    agg = aggregate_ranking(frame, value=value, alpha=alpha)
    csv = agg.table.assign(friedman_statistic=agg.friedman["statistic"], friedman_pvalue=agg.friedman["pvalue"],
                           critical_difference=agg.critical_difference, n_methods=agg.friedman["n_methods"],
                           alpha=alpha)
    return agg, csv


def _aggregate_markdown(agg, to_markdown) -> str:
    lines = ["## Aggregate over scenarios and seeds", "",
             f"Entries ranked inside every block (scenario x seed) by {agg.value}; a block enters when every "
             f"entry has a result in it (Demšar 2006; docs/scoring.md).", ""]
    if len(agg.table):
        lines += [to_markdown(agg.table.round(4), float_format=".4g"), ""]
    lines += [agg.summary(), ""]
    return "\n".join(lines)


def write_views(store, out, tasks) -> pd.DataFrame:
    """Write every view of ``tasks`` from ``store`` into ``out``; returns the board (see :func:`board_table`)."""
    from fuelhm_bench.scoring import to_markdown

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    board = board_table(store, tasks)
    stored = {t.key for t in tasks} & set(store.keys())
    for t in tasks:
        if t.key in stored:
            _method_report(store, out, t)
    for (scenario, seed), group in board.groupby(["scenario", "seed"], sort=False) if len(board) else []:
        _scenario_report(out / f"{scenario}-seed{seed}", scenario, seed, group)
    csv = board.drop(columns=["method_params"], errors="ignore")
    csv.to_csv(out / "leaderboard.csv", index=False)
    agg, agg_csv = aggregate_view(board)
    agg_csv.to_csv(out / "aggregate.csv", index=False)
    agg.pairs.to_csv(out / "aggregate_pairs.csv", index=False)
    cols = [c for c in _MD_COLUMNS if c in board]
    view = board[cols].copy() if len(board) else pd.DataFrame(columns=cols)
    if "message" in view:
        view["message"] = view["message"].fillna("").str.slice(0, 120)
    (out / "leaderboard.md").write_text(
        "# Leaderboard\n\nRanked by summary score (null method = 0, perfect = 100; docs/scoring.md). "
        "Generated from the results store; `params` are the entry's hyperparameters.\n\n"
        + _aggregate_markdown(agg, to_markdown) + "\n## Entries\n\n"
        + to_markdown(view.round(3), float_format=".4g") + "\n")
    from fuelhm_bench.benchmark.page import write_leaderboard_page

    page = board.drop(columns=["method_params", "key"], errors="ignore").copy()
    if len(page):
        page["links"] = [{label: f"{folder}/{name}" for label, name in _PAGE_LINKS} for folder in page["folder"]]
        page = page.drop(columns=["folder"])
    write_leaderboard_page(page, out)  # index.html: links only to files that exist
    return board


def _scenario_report(sdir: Path, scenario: str, seed, group: pd.DataFrame) -> None:
    from fuelhm_bench.scoring import to_markdown

    sdir.mkdir(parents=True, exist_ok=True)
    methods = group.drop(columns=["method_params"], errors="ignore").to_dict("records")
    (sdir / "summary.json").write_text(json.dumps({"scenario": scenario, "seed": int(seed), "methods": methods},
                                                  indent=2, default=str))
    cols = [c for c in _MD_COLUMNS if c in group and c not in ("scenario", "seed", "message")]
    lines = [f"# Evaluation on `{scenario}` (seed {seed})", "", to_markdown(group[cols].round(4)), ""]
    for e in methods:
        lines.append(f"* `{e['method']}` {e['params']}: **{e['status']}** {e.get('message') or ''} "
                     f"(`{Path(e['folder']).name}/`)")
    lines += ["", "Per-method tables: one directory per method setting (CSV, Markdown, LaTeX).", ""]
    (sdir / "report.md").write_text("\n".join(lines))


def _method_report(store, out: Path, task) -> None:
    mdir = method_folder(out, task)
    stamp = mdir / "KEY"
    if stamp.is_file() and stamp.read_text().strip() == task.key:
        return  # up to date: nothing imported (matplotlib and scipy.stats cost a re-run seconds)
    from fuelhm_bench.scoring import (Run, plot_score_distributions, robustness_table, save_figure, score_run,
                                      write_tables)

    mdir.mkdir(parents=True, exist_ok=True)
    rec = store.records([task.key]).to_dict("records")[0]
    (mdir / "result.json").write_text(json.dumps(rec, indent=2, default=str))
    log = out / "logs" / f"{task.key[:16]}.log"
    if log.is_file():
        shutil.copyfile(log, mdir / "method.log")
    decisions = store.artifact(task.key, "decisions")
    if rec["status"] == "ok" and decisions is not None:
        labels = store.artifact(task.key, "labels")
        healthy = store.artifact(task.key, "healthy_scores")["score"].to_numpy()
        run = Run(labels=labels, decisions=decisions, healthy_scores=healthy, name=task.method)
        card = score_run(run)
        write_tables(card, mdir, overwrite=True)
        save_figure(plot_score_distributions(run, card.config), mdir / "score_distributions.png", close=True)
        from fuelhm_bench.scoring.bootstrap import scorecard_intervals
        from fuelhm_bench.scoring.calibration import guilt_calibration, plot_reliability

        scorecard_intervals(card, n_resamples=1000, random_state=task.seed).to_csv(
            mdir / "headline_intervals.csv", index=False)
        reliability = guilt_calibration(card.flights)["reliability"]
        reliability.to_csv(mdir / "reliability.csv", index=False)
        save_figure(plot_reliability({task.method: reliability}), mdir / "reliability.png", close=True)
        decisions.to_csv(mdir / "decisions.csv", index=False)
        store.artifact(task.key, "episodes").to_csv(mdir / "episodes.csv", index=False)
        nominal = store.artifact(task.key, "nominal_decisions")
        if nominal is not None:
            nom = Run(labels=store.artifact(task.key, "nominal_labels"), decisions=nominal,
                      healthy_scores=store.artifact(task.key, "nominal_healthy_scores")["score"].to_numpy(),
                      name=task.method)
            robustness_table(score_run(nom), card).to_csv(mdir / "robustness.csv", index=False)
    stamp.write_text(task.key + "\n")
