"""Tests of the 'validate' and 'schema' commands (fuelhm_bench.cli.validate / .schema)."""

from __future__ import annotations

import json
from pathlib import Path

from fuelhm_bench.cli import main
from fuelhm_bench.scenarios import list_scenarios, scenario_json_schema

BROKEN = Path(__file__).parent / "data" / "scenarios_broken"


def test_validate_valid_file(capsys):
    path = BROKEN / "valid_base.yaml"
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("OK") and "valid_base-v1" in out


def test_validate_shipped(capsys):
    assert main(["validate", "--shipped"]) == 0
    out = capsys.readouterr().out
    for name in list_scenarios():
        assert f"{name} ({name}-v" in out
    assert f"{len(list_scenarios())} valid, 0 invalid" in out


def test_validate_mixed_files_exit_2_and_print_every_error(capsys):
    """An invalid file is bad input: exit status 2, as every command (it was 1)."""
    good, bad = BROKEN / "valid_base.yaml", BROKEN / "several_problems.yaml"
    assert main(["validate", str(good), str(bad), "paper_2012"]) == 2
    out = capsys.readouterr().out
    assert f"OK      {good}" in out and f"INVALID {bad}" in out
    assert f"{bad}:7: fleet.units must be an integer in [1, 10000]. Got 0 instead." in out
    assert f"{bad}:16: sensor.adc_bits" in out and f"{bad}:25: degradations[1].mode" in out
    assert "2 valid, 1 invalid" in out


def test_validate_malformed_and_unknown_name(capsys):
    assert main(["validate", str(BROKEN / "malformed.yaml")]) == 2
    assert "malformed.yaml:24: the document must be well-formed YAML" in capsys.readouterr().out
    assert main(["validate", "paper2012"]) == 2
    assert "Did you mean 'paper_2012'?" in capsys.readouterr().out


def test_validate_without_arguments(capsys):
    assert main(["validate"]) == 2
    assert "error: validate needs at least one FILE or --shipped" in capsys.readouterr().err


def test_no_command_is_a_usage_error(capsys):
    assert main([]) == 2
    assert "error: give a COMMAND" in capsys.readouterr().err


def test_schema_prints_json(capsys):
    assert main(["schema"]) == 0
    assert json.loads(capsys.readouterr().out) == scenario_json_schema()


def test_schema_writes_file_and_refuses_overwrite(tmp_path, capsys):
    out = tmp_path / "sub" / "scenario.schema.json"
    assert main(["schema", "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == scenario_json_schema()
    assert str(out) in capsys.readouterr().out
    assert main(["schema", "--out", str(out)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert main(["schema", "--out", str(out), "--force"]) == 0


def test_validate_refuses_a_copy_that_keeps_another_name(tmp_path, capsys):
    """An edited copy saved as mine.yaml with name: paper_2012 was accepted as paper_2012-v3."""
    path = tmp_path / "mine.yaml"
    path.write_text((Path(__file__).parents[1] / "scenarios" / "paper_2012.yaml").read_text())
    assert main(["validate", str(path)]) == 2
    out = capsys.readouterr().out
    assert f"{path}:5: name must be 'mine', the file's name without its suffix" in out
    assert "Got 'paper_2012' instead" in out and "paper_2012-v3" not in out


def test_evaluate_and_leaderboard_refuse_a_copy_that_keeps_another_name(tmp_path, capsys):
    """The copy was evaluated and ranked as paper_2012-v3, beside (and indistinguishable from) the shipped one."""
    import pytest

    from fuelhm_bench.benchmark.leaderboard import LeaderboardConfig, LeaderboardEntry, plan_tasks
    from fuelhm_bench.errors import ScenarioError

    path = tmp_path / "mine.yaml"
    path.write_text((Path(__file__).parents[1] / "scenarios" / "paper_2012.yaml").read_text())
    assert main(["evaluate", "--scenario", str(path), "--method", "fuelhm_baselines.trivial:NullMethod",
                 "--fidelity", "surrogate", "--out", str(tmp_path / "out")]) == 2
    assert f"{path}:5: name must be 'mine'" in capsys.readouterr().err
    assert not any((tmp_path / "out").rglob("*"))  # nothing written
    with pytest.raises(ScenarioError, match="name must be 'mine'"):
        plan_tasks(LeaderboardConfig((LeaderboardEntry("fuelhm_baselines.trivial:NullMethod"),), (str(path),)))
