"""Leaderboard definition files and a tiny leaderboard run."""

from __future__ import annotations

import pandas as pd
import pytest

from fuelhm_bench.cli import main
from fuelhm_bench.errors import ScenarioError
from fuelhm_bench.benchmark.leaderboard import LeaderboardConfig


def test_shipped_leaderboard_file_loads():
    config = LeaderboardConfig.from_yaml("leaderboard/methods.yaml")
    assert any(m.method == "fuelhm_baselines.trivial:NullMethod" for m in config.methods)
    assert "paper_2012" in config.scenarios


@pytest.mark.parametrize("text, match", [
    ("methods: [a:B]\nscenario: [x]\n", "unknown key 'scenario'.*Did you mean 'scenarios'"),
    ("methods: []\nscenarios: [x]\n", "'methods' must be a non-empty list"),
    # each of these was accepted (or a traceback) before
    ("methods: [{method: a:B, params: {1: 2, a: 3}}]\nscenarios: [x]\n", r"params: hyperparameter names must be "
                                                                       r"Python names. Got 1"),
    ("methods: [{method: a:B, parms: {a: 3}}]\nscenarios: [x]\n", r"methods\[0\]: unknown key 'parms'.*Did you "
                                                                 r"mean 'params'"),
    ("methods: {a: b}\nscenarios: [x]\n", r"'methods' must be a non-empty list. Got \{'a': 'b'\}"),
    ("methods: fuelhm_baselines.trivial:NullMethod\nscenarios: [x]\n", r"'methods' must be a non-empty list. Got "
                                                                        r"'fuelhm_baselines"),
    ("methods: [a:B, a:B]\nscenarios: [x]\n", r"methods\[1\] repeats an earlier entry \(a:B\)"),
    ("methods: [a:B]\nscenarios: [x, x]\n", r"scenarios\[1\] repeats an earlier entry \(x\)"),
    ("methods: [a:B]\nscenarios: [x]\nseeds: 0\n", r"seeds must be a non-empty list .* Got 0"),
    ("methods: [a:B]\nscenarios: [x]\nseeds: []\n", r"seeds must be a non-empty list .* Got \[\]"),
    ("methods: [a:B]\nscenarios: [x]\nseeds: false\n", r"seeds must be a non-empty list .* Got False"),
    ("methods: [a:B]\nscenarios: [x]\nseeds: [1, 1]\n", r"seeds repeats a seed"),
    ("methods: [a:B]\nscenarios: [x]\nscale: 2\n", r"scale is the fraction .* in \(0, 1\]. Got 2"),
    ("methods: [a:B]\nscenarios: [x]\nlimits: {wall_s: 5}\n", r"limits.wall_s: the wall-time limit is the file's "
                                                                r"timeout_s"),
    ("methods: [{method: a:B, params: 3}]\nscenarios: [x]\n", r"methods\[0\].params must be a mapping"),
    ("methods: [a:B\n", r"lb.yaml: not valid YAML \(line 2\)"),
    ("methods: [nocolon]\nscenarios: [x]\n", r"methods\[0\] must look like 'package.module:Class' .* Got 'nocolon'"),
    ("methods: [a:B, {method: 'pkg.mod:B:C'}]\nscenarios: [x]\n", r"methods\[1\].method must look like .* 'pkg.mod:B:C'"),
])
def test_bad_leaderboard_files(tmp_path, text, match):
    path = tmp_path / "lb.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=match):
        LeaderboardConfig.from_yaml(path)


def test_unreadable_leaderboard_files_name_the_file(tmp_path):
    """A binary file (before: UnicodeDecodeError traceback), a directory, a missing file."""
    binary = tmp_path / "board.yaml"
    binary.write_bytes(b"\xff\xfe\x00methods")
    with pytest.raises(ScenarioError, match=r"board.yaml: cannot read the leaderboard file: it is not UTF-8 text"):
        LeaderboardConfig.from_yaml(binary)
    with pytest.raises(ScenarioError, match=r"Cannot read the leaderboard file .*: Is a directory"):
        LeaderboardConfig.from_yaml(tmp_path)
    with pytest.raises(ScenarioError, match=r"Cannot read the leaderboard file .*: No such file"):
        LeaderboardConfig.from_yaml(tmp_path / "missing.yaml")


def test_exponent_notation_is_a_number_in_params(tmp_path):
    """``1e-3`` is a string in YAML 1.1 (PyYAML); every user means a number (reported: ``--param lr=1e-3``
    reached the method as '1e-3')."""
    from fuelhm_bench.benchmark.loading import parse_params

    path = tmp_path / "lb.yaml"
    path.write_text("methods:\n  - method: a.b:C\n    params: {lr: 1e-3, a: 5E0, name: e5}\nscenarios: [paper_2012]\n")
    assert dict(LeaderboardConfig.from_yaml(path).methods[0].params) == {"lr": 0.001, "a": 5.0, "name": "e5"}
    assert parse_params(["lr=1e-3", "n=-2e2", "tag=1e"]) == {"lr": 0.001, "n": -200.0, "tag": "1e"}


def test_tiny_leaderboard_ranks_methods(tmp_path, tiny_scenario):
    scenario = tiny_scenario(tmp_path)
    cfg = tmp_path / "lb.yaml"
    cfg.write_text(f"methods:\n  - fuelhm_baselines.trivial:NullMethod\n  - method: fuelhm_baselines.paper_mahalanobis:PaperMahalanobis\n"
                   f"    params: {{a: 2.0}}\n  - broken.module:Nothing\nscenarios: [{scenario}]\n")
    out = tmp_path / "board"
    # exit status 3: an entry failed (its row says why), as evaluate; the board is written all the same
    assert main(["leaderboard", "--config", str(cfg), "--out", str(out), "--minutes", "4"]) == 3
    board = pd.read_csv(out / "leaderboard.csv")
    ok = board[board["status"] == "ok"]
    assert set(ok["method"]) == {"fuelhm_baselines.paper_mahalanobis:PaperMahalanobis", "fuelhm_baselines.trivial:NullMethod"}
    assert list(ok["summary_score"]) == sorted(ok["summary_score"], reverse=True)  # ranked
    assert ok.set_index("method").loc["fuelhm_baselines.trivial:NullMethod", "summary_score"] == 0.0  # the anchor
    assert (board["status"] == "error").sum() == 1
    assert "Leaderboard" in (out / "leaderboard.md").read_text()
    # statistics in the outputs: unit-bootstrap intervals, guilt calibration, the page
    assert (ok["summary_score_ci_low"] <= ok["summary_score"]).all() and "brier" in board
    page = (out / "index.html").read_text()
    assert "Cannot import the method module" in page and "summary_score" in page and 'id="cd-diagram"' in page


def test_store_keys_follow_every_file_of_the_method(tmp_path, monkeypatch):
    """The key of an evaluation changes when any file the method ships with changes: a sibling module
    of its package, a thresholds file beside a single-file module. Before, only the entry module was
    hashed, so a resumed leaderboard reused a stale result after such an edit (reported: 43.1 reused,
    28.6 for the edited code). Bytecode caches and hidden files do not count."""
    import sys

    from fuelhm_bench.benchmark.leaderboard import LeaderboardEntry, plan_tasks

    pkg = tmp_path / "mypkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from .detector import Det\n")
    (pkg / "detector.py").write_text("from fuelhm_baselines.trivial import NullMethod as Det\n")
    (pkg / "features.py").write_text("SCALE = 1.4826\n")
    (tmp_path / "single.py").write_text("from fuelhm_baselines.trivial import NullMethod as One\n")
    (tmp_path / "single_thresholds.json").write_text('{"a": 3.0}')
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    config = LeaderboardConfig((LeaderboardEntry("mypkg:Det"), LeaderboardEntry("single:One")), ("paper_2012",))

    def keys():
        return [t.key for t in plan_tasks(config)]

    first = keys()
    assert keys() == first  # stable
    (pkg / "__pycache__").mkdir()
    (pkg / "__pycache__" / "features.cpython-311.pyc").write_bytes(b"\0" * 16)
    (tmp_path / ".hidden").write_text("editor state")
    assert keys() == first
    (pkg / "features.py").write_text("SCALE = 3.0\n")
    second = keys()
    assert second[0] != first[0] and second[1] == first[1]
    (tmp_path / "single_thresholds.json").write_text('{"a": 2.0}')
    third = keys()
    assert third[0] == second[0] and third[1] != second[1]
    assert all(t.source_hash for t in plan_tasks(config))
    sys.modules.pop("mypkg", None)


def test_an_edited_copy_of_a_scenario_is_another_key(tmp_path):
    """A copy of paper_2012.yaml with one value changed keeps its name and version; before, it was keyed
    like the shipped file, so a store holding the shipped run answered for it (reported: 82.1 reused,
    91.3 for the edited scenario)."""
    from fuelhm_bench.benchmark.leaderboard import LeaderboardEntry, plan_tasks
    from fuelhm_bench.scenarios.registry import shipped_scenario_files

    text = shipped_scenario_files()["paper_2012"].read_text()
    assert "noise_std_um: 3.0" in text
    copy = tmp_path / "paper_2012.yaml"
    copy.write_text(text)
    edited = tmp_path / "edited" / "paper_2012.yaml"
    edited.parent.mkdir()
    edited.write_text(text.replace("noise_std_um: 3.0", "noise_std_um: 30.0"))

    def key(scenario):
        config = LeaderboardConfig((LeaderboardEntry("fuelhm_baselines.trivial:NullMethod"),), (str(scenario),))
        return plan_tasks(config)[0].key

    assert key("paper_2012") == key(copy)  # the same content, wherever it is read from
    assert key(edited) != key("paper_2012")


def test_two_scenarios_with_one_id_are_refused(tmp_path):
    """Two scenario files with the same name and version (a shipped one and an edited copy, or one listed
    by name and by path) had separate store keys but shared their report folders and leaderboard rows."""
    from fuelhm_bench.benchmark.leaderboard import LeaderboardEntry, plan_tasks
    from fuelhm_bench.scenarios.registry import shipped_scenario_files

    text = shipped_scenario_files()["paper_2012"].read_text()
    edited = tmp_path / "edited" / "paper_2012.yaml"
    edited.parent.mkdir()
    edited.write_text(text.replace("noise_std_um: 3.0", "noise_std_um: 30.0"))
    copy = tmp_path / "paper_2012.yaml"
    copy.write_text(text)

    def plan(*scenarios):
        return plan_tasks(LeaderboardConfig((LeaderboardEntry("fuelhm_baselines.trivial:NullMethod"),), scenarios))

    with pytest.raises(ScenarioError, match=r"'paper_2012' and '.*edited/paper_2012.yaml' are different scenarios "
                                            r"with the same name and version \(paper_2012-v3\).*own name"):
        plan("paper_2012", str(edited))
    with pytest.raises(ScenarioError, match=r"are the same scenario .* List it once"):
        plan("paper_2012", str(copy))
    assert len(plan("paper_2012", "low_data")) == 2
