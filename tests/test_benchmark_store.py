"""The results store: content keys, resume after a kill, views generated from the store, Dask runs."""

from __future__ import annotations

import os
import re
import signal
import sqlite3
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.benchmark.leaderboard import LeaderboardConfig, plan_tasks, run_board
from fuelhm_bench.benchmark.store import ResultStore, evaluation_key
from fuelhm_bench.cli import main
from fuelhm_bench.errors import ScenarioError
from sizes import FLIGHT_MINUTES

METHODS = """methods:
  - fuelhm_baselines.trivial:NullMethod
  - method: fuelhm_baselines.paper_mahalanobis:PaperMahalanobis
    params: {a: 2.0}
  - method: fuelhm_baselines.paper_mahalanobis:PaperMahalanobis
    params: {a: 2.0, window: 5}
"""


@pytest.fixture(scope="module")
def board_config(tmp_path_factory):
    from conftest import _tiny_scenario

    root = tmp_path_factory.mktemp("board")
    scenario = _tiny_scenario(root)
    cfg = root / "lb.yaml"
    cfg.write_text(METHODS + f"scenarios: [{scenario}]\nfidelity: surrogate\ntimeout_s: 300\n")
    return cfg


def _rows(db) -> pd.DataFrame:
    with sqlite3.connect(db) as con:
        return pd.read_sql_query("SELECT key, method, params, status, created FROM results", con)


def test_key_covers_every_field():
    base = dict(method="m:C", params={"a": 2.0}, source_hash="h", scenario="s-v1", seed=1, fidelity="physics",
                scale=1.0, package_version="0.1.0")
    keys = {evaluation_key(**base)}
    for field, value in [("params", {"a": 2.0, "window": 5}), ("params", {"a": 2}), ("source_hash", "g"),
                         ("scenario", "s-v2"), ("seed", 2), ("fidelity", "surrogate"), ("scale", 0.5),
                         ("package_version", "0.2.0"), ("method", "m:D")]:
        keys.add(evaluation_key(**{**base, field: value}))
    assert len(keys) == 10  # 2.0 and 2 are different typed values


@pytest.fixture(scope="module")
def small_board(tmp_path_factory):
    """Two trivial methods on a tiny scenario at physics fidelity (the cheapest data build; flights of
    FLIGHT_MINUTES)."""
    from conftest import _tiny_scenario

    root = tmp_path_factory.mktemp("small-board")
    scenario = _tiny_scenario(root, name="tinyboard")
    cfg = root / "lb.yaml"
    cfg.write_text("methods:\n  - fuelhm_baselines.trivial:NullMethod\n  - fuelhm_baselines.trivial:RandomMethod\n"
                   f"scenarios: [{scenario}]\nfidelity: physics\ntimeout_s: 300\n")
    return LeaderboardConfig.from_yaml(cfg)


class _Killed(BaseException):
    """Stands for the process being killed right after a row is stored."""


def test_interrupted_leaderboard_resumes_only_what_is_missing(small_board, tmp_path):
    """Stopped right after its first stored row, started again: only the missing key is evaluated."""
    out = tmp_path / "board"

    def die_after_first_row(line: str) -> None:
        if ": ok" in line:
            raise _Killed(line)

    with pytest.raises(_Killed):
        run_board(small_board, out, flight_minutes=FLIGHT_MINUTES, log=die_after_first_row)
    first = _rows(out / "results.sqlite")
    assert len(first) == 1
    lines = []
    board = run_board(small_board, out, flight_minutes=FLIGHT_MINUTES, log=lines.append)
    assert lines[0].startswith("1 of 2 evaluations already in") and lines[0].endswith("1 to run.")
    assert sum(": ok" in line for line in lines) == 1  # one evaluation, the missing one
    rows = _rows(out / "results.sqlite")
    assert len(rows) == 2 and set(rows["status"]) == {"ok"} and len(board) == 2
    assert rows.set_index("key").loc[first["key"], "created"].tolist() == first["created"].tolist()
    lines.clear()
    run_board(small_board, out, flight_minutes=FLIGHT_MINUTES, log=lines.append)
    assert lines == [f"2 of 2 evaluations already in {out / 'results.sqlite'}; 0 to run"]


def test_dask_loopback_cluster_runs_the_board(small_board, tmp_path):
    """The Dask path (data build task, then sealed evaluations) on a loopback cluster; same rows as locally."""
    import dataclasses

    from dask.distributed import LocalCluster

    small_board = dataclasses.replace(small_board, methods=small_board.methods[:1])  # one sealed run per path
    local = run_board(small_board, tmp_path / "local", flight_minutes=FLIGHT_MINUTES, log=lambda s: None)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp", host="127.0.0.1",
                      dashboard_address=None, silence_logs=40) as cluster:
        dask = run_board(small_board, tmp_path / "dask", scheduler=cluster.scheduler_address,
                         flight_minutes=FLIGHT_MINUTES, log=lambda s: None)
    cols = ["method", "params", "status", "summary_score", "fpr_standard_thr", "fnr_standard_thr"]
    pd.testing.assert_frame_equal(local[cols], dask[cols])
    with ResultStore(tmp_path / "dask" / "results.sqlite") as store:
        assert store.keys() == {t.key for t in plan_tasks(small_board)}


def _start_environment() -> bytes:
    """The environment this process started with (what glibc read), from /proc."""
    with open("/proc/self/environ", "rb") as f:
        return f.read()


@pytest.mark.skipif(not os.path.exists("/proc/self/environ"), reason="Linux /proc only")
def test_local_cluster_workers_start_with_one_malloc_arena():
    """--jobs N: the workers start with MALLOC_ARENA_MAX=1 (set before the spawn, so glibc reads it),
    which keeps a build on the worker's task thread on the main heap (docs/methods.md)."""
    from fuelhm_bench.benchmark.distributed import WORKER_ENVIRONMENT, _client

    client, cluster = _client(1, None)
    try:
        started = list(client.run(_start_environment).values())
    finally:
        client.close()
        cluster.close()
    assert len(started) == 1
    for key, value in WORKER_ENVIRONMENT.items():
        assert f"{key}={value}".encode() in started[0].split(b"\0")


def test_raw_signal_method_gets_a_leaderboard_row(small_board, tmp_path):
    """The raw-signal baseline from the config file to a stored, scored row (physics: it gets its flights)."""
    rows = run_board(_with_raw(small_board), tmp_path / "physics", flight_minutes=FLIGHT_MINUTES, log=lambda s: None)
    got = rows.set_index("method")
    assert got.loc["fuelhm_baselines.raw_tracking:RawTrackingMethod", "status"] == "ok"
    assert np.isfinite(got.loc["fuelhm_baselines.raw_tracking:RawTrackingMethod", "summary_score"])


@pytest.mark.slow  # builds the surrogate (about 10 s); the harness's refusal runs by default in test_benchmark_raw
def test_raw_signal_method_is_refused_on_a_surrogate_board(small_board, tmp_path):
    """At surrogate fidelity the raw method's row says why it was refused; the other entry's row is unaffected."""
    import dataclasses

    surrogate = dataclasses.replace(_with_raw(small_board), fidelity="surrogate")
    rows = run_board(surrogate, tmp_path / "surrogate", flight_minutes=FLIGHT_MINUTES,
                     log=lambda s: None).set_index("method")
    assert rows.loc["fuelhm_baselines.raw_tracking:RawTrackingMethod", "status"] == "refused"
    assert "raw" in rows.loc["fuelhm_baselines.raw_tracking:RawTrackingMethod", "message"]
    assert rows.loc["fuelhm_baselines.trivial:NullMethod", "status"] == "ok"


def _with_raw(board):
    """The board's first entry and the raw-signal baseline."""
    import dataclasses

    from fuelhm_bench.benchmark.leaderboard import LeaderboardEntry

    raw = LeaderboardEntry("fuelhm_baselines.raw_tracking:RawTrackingMethod")
    return dataclasses.replace(board, methods=(board.methods[0], raw))


@pytest.mark.slow  # about 2 minutes on the loaded 2-core machine (three runs of a subprocess leaderboard)
def test_killed_leaderboard_resumes_only_what_is_missing(board_config, tmp_path):
    """Killed (SIGKILL, whole group) after the first stored row, restarted: only the missing keys run."""
    out = tmp_path / "board"
    cmd = [sys.executable, "-m", "fuelhm_bench.cli", "leaderboard", "--config", str(board_config), "--out", str(out)]
    env = {**os.environ, "FUELHM_NO_PROGRESS": "1"}
    proc = subprocess.Popen(cmd, env=env, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    db = out / "results.sqlite"
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        if db.is_file():
            try:
                if len(_rows(db)) >= 1:
                    break
            except (sqlite3.Error, pd.errors.DatabaseError):
                pass
        if proc.poll() is not None:
            pytest.fail(f"the run ended before it could be killed: {proc.stderr.read().decode()[-2000:]}")
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    first = _rows(db)
    assert 1 <= len(first) < 3
    # a second run: refuses nothing (the folder holds a store), evaluates only the rest
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"{len(first)} of 3 evaluations already in" in done.stderr
    rows = _rows(db)
    assert len(rows) == 3 and set(rows["status"]) == {"ok"}
    kept = rows.set_index("key").loc[first["key"], "created"]
    assert list(kept) == list(first["created"])  # the stored rows were not evaluated again
    # two settings of one class: separate rows, folders and board lines with their parameters
    board = pd.read_csv(out / "leaderboard.csv")
    assert "Unnamed: 0" not in board.columns and "index" not in board.columns
    paper = board[board["method"].str.contains("PaperMahalanobis")]
    assert sorted(paper["params"]) == ['{"a": 2.0, "window": 5}', '{"a": 2.0}']
    assert paper["folder"].nunique() == 2 and all((out / f).is_dir() for f in board["folder"])
    assert "params" in (out / "leaderboard.md").read_text()
    # a third run stores nothing new; --rerun evaluates again
    again = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    assert again.returncode == 0 and "3 of 3 evaluations already in" in again.stderr
    assert list(_rows(db)["created"]) == list(rows["created"])


def test_output_folder_without_store_is_not_overwritten(board_config, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("precious")
    assert main(["leaderboard", "--config", str(board_config), "--out", str(out)]) == 2
    assert "not empty and holds no results store" in capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "precious"


@pytest.mark.parametrize("text, match", [
    ("scale: fast\n", r"scale must be a finite number > 0. Got 'fast' instead"),
    ("scale: -1\n", r"scale must be a finite number > 0. Got -1 instead"),
    ("timeout_s: .inf\n", r"timeout_s must be a finite number > 0"),
    ("seeds: [x]\n", r"seeds must be a non-empty list of integers"),
    ("limits: {memory_mb: 10}\n", r"limits: The 'memory_mb' parameter of Limits must be"),
    ("limits: {cpu: 10}\n", r"limits: unknown limit 'cpu'"),
    ("secret_seeds: 2\nseeds: [1]\n", r"give seeds or secret_seeds, not both"),
    ("secret_seeds: -1\n", r"secret_seeds must be an integer in \[0, 100\]"),
    ("secret_seeds: yes\n", r"secret_seeds must be an integer in \[0, 100\] .*Got True"),
])
def test_bad_config_values_name_the_field(tmp_path, text, match):
    cfg = tmp_path / "lb.yaml"
    cfg.write_text("methods: [a:B]\nscenarios: [paper_2012]\n" + text)
    with pytest.raises(ScenarioError, match=re.escape(str(cfg)) + ": " + match):
        LeaderboardConfig.from_yaml(cfg)


@pytest.mark.slow  # a local Dask cluster and two leaderboard runs: about a minute
def test_dask_local_cluster_matches_the_local_run(board_config, tmp_path):
    """--jobs 2: data builds and sealed evaluations as Dask tasks on a loopback cluster; same results."""
    config = LeaderboardConfig.from_yaml(board_config)
    config = LeaderboardConfig(config.methods[:2], config.scenarios, config.seeds, config.scale, config.timeout_s,
                               config.fidelity)
    local = run_board(config, tmp_path / "local", log=lambda s: None)
    dask = run_board(config, tmp_path / "dask", jobs=2, log=lambda s: None)
    cols = ["method", "params", "status", "summary_score", "fpr_standard_thr", "fnr_standard_thr"]
    pd.testing.assert_frame_equal(local[cols], dask[cols])
    with ResultStore(tmp_path / "dask" / "results.sqlite") as store:
        assert store.keys() == {t.key for t in plan_tasks(config)}
        rec = store.records().iloc[0]
        assert rec["provenance"]["package_version"] and rec["provenance"]["python"]
        assert rec["provenance"]["host"] and rec["created"]


def test_secret_seeds_are_drawn_once_kept_in_the_store_and_hidden_from_the_plan(small_board, tmp_path):
    """With the scenario's public master seed a submission rebuilt the scored fleet's fault schedule
    from the public scenario file and scored 100 (probe4). Secret seeds are drawn from the OS, kept in the
    store (a folder sealed methods cannot read) and reused when the run resumes."""
    import dataclasses

    from fuelhm_bench.scenarios import load_scenario

    public = load_scenario(small_board.scenarios[0]).seeds.master
    config = dataclasses.replace(small_board, methods=small_board.methods[:1], secret_seeds=2)
    lines = []
    board = run_board(config, tmp_path / "a", flight_minutes=FLIGHT_MINUTES, log=lines.append)
    with ResultStore(tmp_path / "a" / "results.sqlite") as store:
        seeds = store.secret_seeds(2)
        recorded = sorted(store.records()["seed"])
    assert len(set(seeds)) == 2 and public not in seeds and recorded == sorted(seeds)
    assert len(board) == 2 and (board["status"] == "ok").all()
    assert any("2 secret seed(s), kept in" in s for s in lines)
    lines.clear()
    run_board(config, tmp_path / "a", flight_minutes=FLIGHT_MINUTES, log=lines.append)  # resumed: the same seeds
    assert any("2 of 2 evaluations already in" in s for s in lines)
    with ResultStore(tmp_path / "b" / "results.sqlite") as other:  # another store, other seeds
        assert not set(other.secret_seeds(2)) & set(seeds)


def test_seed_and_secret_seeds_are_exclusive(tmp_path):
    assert main(["evaluate", "--method", "a:B", "--scenario", "paper_2012", "--seed", "1", "--secret-seeds", "1",
                 "--out", str(tmp_path / "o")]) == 2
    assert not (tmp_path / "o").exists()
