"""Tests of the shipped-scenario registry: names, name-vN, retired versions (fuelhm_bench.scenarios.registry)."""

from __future__ import annotations

import re

import pytest

from fuelhm_bench.errors import ScenarioError, UnknownNameError
from fuelhm_bench.scenarios import list_scenarios, load_scenario


def test_list_scenarios_is_sorted_names():
    names = list_scenarios()
    assert names == tuple(sorted(names)) and "all_modes" in names
    assert all("-" not in n and not n.endswith(".yaml") for n in names)


def test_load_by_name_and_by_current_version():
    scenario = load_scenario("all_modes")
    assert load_scenario(scenario.id) == scenario
    assert scenario.id == f"all_modes-v{scenario.version}"


def test_retired_version_names_the_current_one():
    current = load_scenario("all_modes")
    retired = f"all_modes-v{current.version - 1}"
    with pytest.raises(ScenarioError) as info:
        load_scenario(retired)
    message = str(info.value)
    assert f"'{retired}' is retired" in message
    assert f"the current version is '{current.id}'" in message


def test_future_version_names_the_current_one():
    current = load_scenario("paper_2012")
    with pytest.raises(ScenarioError, match=rf"'paper_2012-v{current.version + 5}' does not exist; "
                                            rf"the current version is '{current.id}'"):
        load_scenario(f"paper_2012-v{current.version + 5}")


def test_retired_version_of_a_copy_with_a_higher_version(tmp_path, monkeypatch):
    """Lower versions than the shipped file's are retired, whatever the number."""
    import fuelhm_bench.scenarios.registry as registry

    text = re.sub(r"^version: \d+\b", "version: 3", registry.shipped_scenario_files()["low_data"].read_text(),
                  flags=re.M)
    (tmp_path / "low_data.yaml").write_text(text)
    monkeypatch.setattr(registry, "_shipped_directory", lambda: tmp_path)
    assert load_scenario("low_data").id == "low_data-v3"
    with pytest.raises(ScenarioError, match="'low_data-v2' is retired; the current version is 'low_data-v3'"):
        load_scenario("low_data-v2")


def test_unknown_name_lists_shipped_and_suggests():
    with pytest.raises(UnknownNameError) as info:
        load_scenario("all_mode")
    message = str(info.value)
    assert "Unknown scenario 'all_mode'" in message
    assert ", ".join(list_scenarios()) in message
    assert "Did you mean 'all_modes'?" in message
    with pytest.raises(UnknownNameError, match="Did you mean 'multi_fault'"):
        load_scenario("multi_fault-v1".replace("multi_", "mutli_"))


def test_shipped_name_must_match_the_file(tmp_path, monkeypatch):
    import fuelhm_bench.scenarios.registry as registry

    text = registry.shipped_scenario_files()["low_data"].read_text()
    (tmp_path / "other.yaml").write_text(text)
    monkeypatch.setattr(registry, "_shipped_directory", lambda: tmp_path)
    with pytest.raises(ScenarioError, match="other.yaml:4: name must be 'other', the file's name .* "
                                            "Got 'low_data' instead"):
        load_scenario("other")


def test_paths_are_loaded_as_files(tmp_path):
    with pytest.raises(ScenarioError, match="Cannot read the scenario file"):
        load_scenario(tmp_path / "nothing_here.yaml")
    with pytest.raises(ScenarioError, match="Cannot read the scenario file"):
        load_scenario("no/such/dir")
