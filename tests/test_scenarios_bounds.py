"""Scenario files that try to hurt: alias bombs, deep nesting, huge fleets, over-budget runs.

Each kind of bad input is refused with the project's own error naming the
file, fast and in little memory (issue 9 section 3).
"""

from __future__ import annotations

import math
import re
import time
import tracemalloc
from pathlib import Path

import pytest
import yaml

from fuelhm_bench.errors import FuelHMError, ScenarioError
from fuelhm_bench.scenarios import (
    DEFAULT_RUN_BUDGET_FLIGHT_HOURS,
    MAX_UNITS,
    RUN_BUDGET_ENV,
    load_scenario,
    load_scenario_file,
    parse_scenario,
)
from fuelhm_bench.scenarios.loader import MAX_DEPTH, MAX_EXPANDED_NODES, MAX_FILE_BYTES

ROOT = Path(__file__).resolve().parents[1]
PAPER = (ROOT / "scenarios" / "paper_2012.yaml").read_text()


def billion_laughs(levels: int = 12) -> str:
    lines = ['a0: &a0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    lines += [f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, levels)]
    return "\n".join(lines) + f"\nname: *a{levels - 1}\n"


def refuse_quickly(text: str, path: Path, budget_s: float = 1.0, budget_mb: float = 40.0) -> str:
    path.write_text(text)
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(ScenarioError) as info:
            load_scenario_file(path)
    finally:
        elapsed = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
    assert elapsed < budget_s and peak < budget_mb, (elapsed, peak)
    message = str(info.value)
    assert message.startswith(str(path)), message
    return message


def test_billion_laughs_is_refused_fast(tmp_path):
    text = billion_laughs()
    assert len(text) < 1024
    message = refuse_quickly(text, tmp_path / "lol.yaml")
    assert f"at most {MAX_EXPANDED_NODES} YAML values once its aliases (*name) are expanded" in message


def test_billion_laughs_through_gym_make(tmp_path):
    gym = pytest.importorskip("gymnasium")
    import fuelhm_bench.envs  # noqa: F401 (registers the ids)

    path = tmp_path / "lol.yaml"
    path.write_text(billion_laughs())
    with pytest.raises(FuelHMError, match=re.escape(str(path))):
        gym.make("FuelHM/ActuationLoop-v3", scenario=str(path))


@pytest.mark.parametrize("text", [
    "x: " + "[" * 5000 + "]" * 5000,
    "x: " + "{a: " * 3000 + "1" + "}" * 3000,
    "x:\n" + "".join("  " * i + f"k{i}:\n" for i in range(1, 120)) + "  " * 120 + "v: 1\n",
    "x:\n" + "".join("  " * i + "-\n" for i in range(1, 120)) + "  " * 120 + "- 1\n",
], ids=["flow-lists", "flow-maps", "block-maps", "block-lists"])
def test_deep_nesting_is_refused_without_recursion_error(tmp_path, text):
    message = refuse_quickly(text, tmp_path / "deep.yaml")
    assert f"nested at most {MAX_DEPTH} levels deep" in message


def test_alias_chain_deeper_than_the_bound_is_refused(tmp_path):
    text = "\n".join(["a0: &a0 [1]"] + [f"a{i}: &a{i} [*a{i - 1}]" for i in range(1, 300)])
    message = refuse_quickly(text, tmp_path / "chain.yaml")
    assert "aliases (*name) expanded" in message


def test_recursive_alias_is_refused(tmp_path):
    message = refuse_quickly("a: &x [1, *x]\nname: *x\n", tmp_path / "rec.yaml")
    assert "recursive alias" in message


def test_oversized_file_is_refused(tmp_path):
    text = PAPER + "\n# " + "x" * MAX_FILE_BYTES + "\n"
    message = refuse_quickly(text, tmp_path / "big.yaml")
    assert f"at most {MAX_FILE_BYTES} bytes" in message


def test_huge_value_is_not_repr_in_full():
    text = PAPER.replace("description:", "description: &d [" + ",".join(["1"] * 5000) + "]\nx_description:", 1)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, "f.yaml")
    assert all(len(line) < 400 for line in str(info.value).splitlines())


def _with(text: str, old: str, new: str) -> str:
    assert old in text
    return text.replace(old, new, 1)


@pytest.mark.parametrize("old,new,field,allowed", [
    ("units: 30                  # units", "units: 1e26 #", "fleet.units", f"an integer in [1, {MAX_UNITS}]"),
    ("units: 30                  # units", "units: 100000000000000000000000000 #", "fleet.units",
     f"an integer in [1, {MAX_UNITS}]"),
    ("flights_per_unit: 30", "flights_per_unit: 1000000000000", "fleet.flights_per_unit",
     "an integer in [1, 10000]"),
    ("duration_min: 25.0", "duration_min: 1e9", "mission.duration_min", "a number in (0, 1440]"),
])
def test_fleet_sizes_have_upper_bounds(old, new, field, allowed):
    with pytest.raises(ScenarioError) as info:
        parse_scenario(_with(PAPER, old, new), "big.yaml")
    assert re.search(rf"big\.yaml:\d+: {re.escape(field)} must be {re.escape(allowed)}\.", str(info.value)), \
        str(info.value)


def _large_paper() -> str:
    text = _with(PAPER, "units: 30                  # units", "units: 2000 #")
    return _with(text, "flights_per_unit: 30", "flights_per_unit: 100")


def test_run_over_budget_is_refused_with_its_estimate(monkeypatch):
    monkeypatch.delenv(RUN_BUDGET_ENV, raising=False)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(_large_paper(), "large.yaml")
    message = str(info.value)
    hours = (2000 * 100 + 200 * 2) * 25 / 60  # + the 200 x 2 training fleet
    assert f"fleet must be a run within the budget of {DEFAULT_RUN_BUDGET_FLIGHT_HOURS:g} flight-hours" in message
    assert f"{hours:.4g} flight-hours (scored fleet 2000 units x 100 flights" in message
    assert "of simulation on one core at 100 Hz" in message
    assert f"run_budget_flight_hours: {math.ceil(hours)}" in message and RUN_BUDGET_ENV in message


def test_run_budget_opt_in_by_field_and_by_environment(monkeypatch):
    monkeypatch.delenv(RUN_BUDGET_ENV, raising=False)
    text = _large_paper() + "run_budget_flight_hours: 90000\n"
    assert parse_scenario(text, "large.yaml").run_cost().flight_hours == pytest.approx((200000 + 400) * 25 / 60)
    monkeypatch.setenv(RUN_BUDGET_ENV, "1e5")
    assert parse_scenario(_large_paper(), "large.yaml").fleet.units == 2000
    monkeypatch.setenv(RUN_BUDGET_ENV, "lots")
    with pytest.raises(ScenarioError, match=f"{RUN_BUDGET_ENV} must be a number of flight-hours > 0. Got 'lots'"):
        parse_scenario(_large_paper(), "large.yaml")


def test_shipped_scenarios_are_within_the_default_budget(monkeypatch):
    monkeypatch.delenv(RUN_BUDGET_ENV, raising=False)
    from fuelhm_bench.scenarios import list_scenarios

    assert max(load_scenario(n).run_cost().flight_hours for n in list_scenarios()) < DEFAULT_RUN_BUDGET_FLIGHT_HOURS


def test_probability_sum_blames_the_changed_degradation():
    raw = yaml.safe_load(PAPER)
    assert raw["degradations"][1]["probability"] == 0.35
    text = _with(PAPER, "probability: 0.35", "probability: 0.35")  # first one unchanged
    head, sep, tail = text.partition("probability: 0.35")
    text = head + sep + tail.replace("probability: 0.35", "probability: 0.45", 1)  # change the second
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, "paper.yaml")
    (problem,) = info.value.problems
    assert problem.field == "degradations[1].probability"
    assert "was 0.35 in the shipped paper_2012; 0.35 would make the sum 1." in str(info.value)


def test_probability_sum_blames_healthy_probability_when_it_changed():
    text = _with(PAPER, "healthy_probability: 0.30", "healthy_probability: 0.50")
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, "paper.yaml")
    assert info.value.problems[0].field == "healthy_probability"


def test_probability_sum_without_a_shipped_baseline_blames_the_largest_excess():
    text = _with(PAPER, "name: paper_2012", "name: my_own")
    text = _with(text, "probability: 0.35", "probability: 0.95")
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, "own.yaml")
    (problem,) = info.value.problems
    assert problem.field == "degradations[0].probability"
    assert "alone sum to 1.3 > 1" in str(info.value)


def test_validate_command_refuses_the_bomb_with_one_message(tmp_path, capsys):
    from fuelhm_bench.cli import main

    path = tmp_path / "lol.yaml"
    path.write_text(billion_laughs())
    assert main(["validate", str(path)]) == 2
    out = capsys.readouterr().out
    assert f"INVALID {path}" in out and "once its aliases (*name) are expanded" in out
    assert len(out) < 2000
