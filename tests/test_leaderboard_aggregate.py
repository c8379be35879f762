"""The aggregate over scenarios and seeds in leaderboard.md and aggregate.csv, generated from the results store."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from fuelhm_bench.benchmark.leaderboard import Task
from fuelhm_bench.benchmark.store import ResultStore
from fuelhm_bench.benchmark.views import write_views
from fuelhm_bench.scoring.ranking import aggregate_ranking

METHODS = ("m:Good", "m:Mid", "m:Bad")
# summary scores per block (scenario, seed): Good wins 5 of 6 blocks, Mid beats it once
SCORES = {("s1", 0): (80, 40, 10), ("s1", 1): (75, 45, 5), ("s2", 0): (60, 65, 20),
          ("s2", 1): (70, 50, 30), ("s3", 0): (90, 30, 35), ("s3", 1): (85, 20, 10)}


@pytest.fixture
def board(tmp_path):
    out = tmp_path / "board"
    store = ResultStore(out / "results.sqlite")
    tasks = []
    for (scenario, seed), values in SCORES.items():
        for method, value in zip(METHODS, values):
            key = f"{method}-{scenario}-{seed}"
            tasks.append(Task(key, method, (), (), scenario, scenario, seed, "physics", 1.0))
            store.put({"key": key, "method": method, "params": {}, "source_hash": "", "scenario": scenario,
                       "seed": seed, "fidelity": "physics", "scale": 1.0, "package_version": "test", "status": "ok",
                       "message": "", "kpis": {"summary_score": float(value)}, "method_params": {},
                       "fit_seconds": 0.1, "decide_seconds": 0.1, "seconds": 0.2, "provenance": {}})
    key = "m:Broken-s1-0"  # a failed entry is listed but never ranked
    tasks.append(Task(key, "m:Broken", (), (), "s1", "s1", 0, "physics", 1.0))
    store.put({"key": key, "method": "m:Broken", "params": {}, "source_hash": "", "scenario": "s1", "seed": 0,
               "fidelity": "physics", "scale": 1.0, "package_version": "test", "status": "refused",
               "message": "m:Broken needs the raw flights", "kpis": {}, "method_params": {}, "fit_seconds": None,
               "decide_seconds": None, "seconds": 0.0, "provenance": {}})
    write_views(store, out, tasks)
    store.close()
    return out


def test_aggregate_csv_holds_mean_ranks_and_the_tests(board):
    agg = pd.read_csv(board / "aggregate.csv")
    assert agg["method"].tolist() == list(METHODS)  # best mean rank first; the refused entry is not ranked
    ranks = np.array([stats.rankdata([-v for v in values]) for values in SCORES.values()])
    np.testing.assert_allclose(agg["mean_rank"], ranks.mean(axis=0))
    assert (agg["n_blocks"] == 6).all()
    friedman = stats.friedmanchisquare(*ranks.T)
    np.testing.assert_allclose(agg["friedman_pvalue"], friedman.pvalue)
    np.testing.assert_allclose(agg["friedman_statistic"], friedman.statistic)
    cd = stats.studentized_range.ppf(0.95, 3, np.inf) / np.sqrt(2) * np.sqrt(3 * 4 / (6 * 6))
    np.testing.assert_allclose(agg["critical_difference"], cd)
    # Good (1.17) vs Bad (2.83): gap 1.67 > CD 1.35; Good vs Mid (2.0): gap 0.83 < CD
    assert agg["nemenyi_differs_from_best"].tolist() == [False, False, True]
    pairs = pd.read_csv(board / "aggregate_pairs.csv")
    assert len(pairs) == 3 and set(pairs.columns) >= {"pvalue", "pvalue_holm", "significant"}


def test_leaderboard_md_opens_with_the_aggregate(board):
    text = (board / "leaderboard.md").read_text()
    head, entries = text.split("## Entries")
    assert "## Aggregate over scenarios and seeds" in head
    assert head.index("m:Good") < head.index("m:Mid") < head.index("m:Bad") and "m:Broken" not in head
    p = pd.read_csv(board / "aggregate.csv")["friedman_pvalue"].iloc[0]
    assert f"p = {p:.3g}" in head and "Nemenyi critical difference" in head and "Wilcoxon" in head
    assert "m:Broken" in entries and "refused" in entries


def test_aggregate_names_settings_only_when_a_method_has_several():
    r = pd.DataFrame({"method": ["a", "a", "b"] * 2, "params": ['{"k": 1}', '{"k": 2}', "{}"] * 2,
                      "scenario": ["x"] * 3 + ["y"] * 3, "summary_score": [3.0, 2.0, 1.0, 2.0, 3.0, 1.0]})
    table = aggregate_ranking(r).table
    assert sorted(table["method"]) == ['a {"k": 1}', 'a {"k": 2}', "b"]
    one = aggregate_ranking(r.iloc[[0, 2]])
    assert one.table["method"].tolist() == ["a", "b"] and one.friedman["pvalue"] != one.friedman["pvalue"]
