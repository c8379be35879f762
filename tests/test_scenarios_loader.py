"""Tests of scenario loading from YAML: located, complete error messages (fuelhm_bench.scenarios.loader)."""

from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path

import pytest
import yaml

from fuelhm_bench.errors import FuelHMError, ParameterError, ScenarioError
from fuelhm_bench.scenarios import (
    Problem,
    Scenario,
    ScenarioValidationError,
    load_scenario,
    load_scenario_file,
    parse_scenario,
)
from fuelhm_bench.scenarios import schema as schema_module

BROKEN = Path(__file__).parent / "data" / "scenarios_broken"
VALID_BASE = BROKEN / "valid_base.yaml"

#: file -> (line, field path, allowed (substring), given (substring), hint (substring or None))
CASES = {
    "malformed": (24, "", "well-formed YAML (mapping values are not allowed here", "'growth: linear: fast'", None),
    "unknown_key_typo": (8, "fleet.flights_per_unti", "units, flights_per_unit, dispersion_scale",
                         "'flights_per_unti'", "Did you mean 'flights_per_unit'?"),
    "wrong_type": (16, "sensor.adc_bits", "an integer in [0, 24]", "'twelve'", None),
    "out_of_range": (26, "degradations[1].probability", "a number in [0, 1]", "1.25", None),
    "unknown_mode": (25, "degradations[1].mode", "one of filter_contamination, null_bias_drift", "'internal_leak'",
                     "Did you mean 'internal_leakage'?"),
    "unknown_effect": (31, "hidden_effects[0].effect", "one of spool_overlap, spool_flow_force, rod_friction",
                       "'rod_frict'", "Did you mean 'rod_friction'?"),
    "onset_after_last_flight": (22, "degradations[0].onset_min", "<= the last flight index, flights_per_unit - 1 = 9",
                                "12", None),
    "probabilities_not_one": (18, "healthy_probability", "sum to 1 when simultaneous is false (0.25 + 0.25 + 0.4 = 0.9",
                              "0.4", "healthy_probability: 0.5 would make them sum to 1."),
    "unknown_drift_parameter": (35, "drift[0].parameter", "servovalve.{rated_current_a,", "'servovalve.spool_time_constant'",
                                "Did you mean 'servovalve.spool_time_constant_s'?"),
    "growth_typo": (29, "degradations[1].growth", "one of step, linear, exponential", "'expo'",
                    "Did you mean 'exponential'?"),
    "effect_parameter_out_of_range": (33, "hidden_effects[0].parameters.coulomb_n", "in (0, 5000] (RodFriction.coulomb_n)",
                                      "9000.0", None),
    "drift_breaks_physics": (37, "drift[0].value", "ServovalveParams.spool_time_constant_s is in [1e-05, 0.1]", "50.0",
                             "from 0.0025 to 0.1275"),
    "missing_key": (12, "seeds.master", "given (an integer in [0, 9223372036854775807])", "nothing (the key is missing)", None),
    "duplicate_key": (8, "fleet.units", "given once in its mapping", "'units'", None),
    "future_schema_version": (2, "schema_version", "one of 1", "2", "newer fuelhm-bench"),
    "dispersion_too_large": (9, "fleet.dispersion_scale", "a number in [0, 3]", "5", None),
    "cost_too_large": (13, "costs.failure_kusd", "a number in [0, 1000000]", "1e+308", None),
    "name_not_file_name": (3, "name", "'name_not_file_name', the file's name without its suffix", "'paper_2012'",
                           "Set name: name_not_file_name, or rename the file to paper_2012.yaml."),
}


def _single_problem(path: Path) -> tuple[Problem, str]:
    with pytest.raises(ScenarioError) as info:
        load_scenario_file(path)
    exc = info.value
    assert isinstance(exc, ScenarioValidationError)
    assert len(exc.problems) == 1, str(exc)
    return exc.problems[0], str(exc)


def test_valid_base_loads():
    """The broken files differ from this valid file by one defect each."""
    scenario = load_scenario_file(VALID_BASE)
    assert scenario.id == "valid_base-v1"
    assert [d.mode for d in scenario.degradations] == ["null_bias_drift", "internal_leakage"]


def test_every_broken_file_is_covered():
    files = {p.stem for p in BROKEN.glob("*.yaml")} - {"valid_base", "several_problems"}
    assert files == set(CASES)


@pytest.mark.parametrize("name", sorted(CASES))
def test_broken_file_message(name):
    line, field, allowed, given, hint = CASES[name]
    path = BROKEN / f"{name}.yaml"
    problem, message = _single_problem(path)
    assert problem.source == str(path)
    assert problem.line == line
    assert problem.field == field
    assert allowed in problem.allowed
    assert given in problem.given
    if hint is not None:
        assert hint in problem.hint
    # Everything is in the one-line message, in the documented order.
    assert message.startswith(f"{path}:{line}: {field}")
    for part in (allowed, given) + ((hint,) if hint else ()):
        assert part in message
    assert "\n" not in message


def test_brief_example_wording():
    _, message = _single_problem(BROKEN / "growth_typo.yaml")
    assert message.endswith("degradations[1].growth must be one of step, linear, exponential. "
                            "Got 'expo' instead. Did you mean 'exponential'?")


def test_several_problems_are_all_reported_in_line_order():
    path = BROKEN / "several_problems.yaml"
    with pytest.raises(ScenarioValidationError) as info:
        load_scenario_file(path)
    problems = info.value.problems
    assert [(p.line, p.field) for p in problems] == [
        (7, "fleet.units"), (16, "sensor.adc_bits"), (25, "degradations[1].mode")]
    lines = str(info.value).splitlines()
    assert len(lines) == 3 and all(line.startswith(f"{path}:") for line in lines)


def test_future_schema_version_hides_other_problems():
    """A newer format is refused before its (unknown) keys are looked at."""
    problem, message = _single_problem(BROKEN / "future_schema_version.yaml")
    assert "new_section" not in message


def test_errors_are_fuelhm_errors_and_pickle():
    with pytest.raises(FuelHMError) as info:
        load_scenario_file(BROKEN / "several_problems.yaml")
    copy = pickle.loads(pickle.dumps(info.value))
    assert str(copy) == str(info.value)
    assert copy.problems == info.value.problems


def _base_text() -> str:
    return VALID_BASE.read_text()


def test_unknown_top_level_key():
    text = _base_text().replace("simultaneous: false", "simultaneus: false\nsimultaneous: false")
    with pytest.raises(ScenarioValidationError) as info:
        parse_scenario(text, source="x.yaml")
    (problem,) = info.value.problems
    assert problem.field == "simultaneus" and problem.line == 17
    assert "top-level keys must be one of schema_version, name, version" in str(info.value)
    assert "Did you mean 'simultaneous'?" in str(info.value)


def test_unknown_effect_parameter_is_an_unknown_key():
    text = _base_text().replace("      coulomb_n: 150.0", "      coulomb_n: 150.0\n      static_ration: 1.2")
    with pytest.raises(ScenarioValidationError) as info:
        parse_scenario(text, source="x.yaml")
    (problem,) = info.value.problems
    assert problem.unknown_key and problem.line == 34
    assert problem.field == "hidden_effects[0].parameters.static_ration"
    assert "coulomb_n, static_ratio, stribeck_velocity_m_s, viscous_n_s_m" in problem.allowed
    assert problem.hint == "Did you mean 'static_ratio'?"


def test_section_of_wrong_shape():
    text = _base_text().replace("fleet:\n  units: 4\n  flights_per_unit: 10\n", "fleet: 4\n")
    with pytest.raises(ScenarioValidationError) as info:
        parse_scenario(text, source="x.yaml")
    (problem,) = info.value.problems
    assert (problem.field, problem.line, problem.given) == ("fleet", 6, "4")
    assert "a mapping with the keys units, flights_per_unit, dispersion_scale" in problem.allowed


def test_list_of_wrong_shape():
    text = _base_text().replace("drift:\n", "drift: servovalve.lap_m\n").split("  - parameter:")[0]
    with pytest.raises(ScenarioValidationError) as info:
        parse_scenario(text, source="x.yaml")
    (problem,) = info.value.problems
    assert problem.field == "drift" and "a list of mappings (DriftSpec)" in problem.allowed


@pytest.mark.parametrize("text, line", [
    ("", 1),
    ("- just\n- a list\n", 1),
    ("schema_version: 1\nname: [unclosed\n", 3),
    ("a: 1\n---\nb: 2\n", 2),
])
def test_not_a_scenario_document(text, line):
    with pytest.raises(ScenarioValidationError) as info:
        parse_scenario(text, source="x.yaml")
    (problem,) = info.value.problems
    assert problem.source == "x.yaml" and problem.line == line


def test_plain_exponent_notation_is_a_number():
    """YAML 1.1 reads 1e-5 (no dot) as a string; number fields accept it."""
    text = _base_text().replace("  - effect: rod_friction\n    parameters:\n      coulomb_n: 150.0",
                                "  - effect: spool_overlap\n    parameters:\n      overlap_m: 2e-5")
    scenario = parse_scenario(text)
    assert scenario.hidden_effects[0].parameters == (("overlap_m", 2e-5),)
    quoted = text.replace("overlap_m: 2e-5", "overlap_m: '2e-5'")
    with pytest.raises(ScenarioValidationError, match=r"parameters.overlap_m must be a number"):
        parse_scenario(quoted)


def test_anchors_and_merge_keys():
    text = _base_text().replace(
        "degradations:\n  - mode: null_bias_drift\n    probability: 0.25\n    onset_min: 2\n    onset_max: 5\n"
        "    growth: linear\n  - mode: internal_leakage\n    probability: 0.25\n    onset_min: 2\n    onset_max: 5\n"
        "    growth: linear\n",
        "degradations:\n  - &base {mode: null_bias_drift, probability: 0.25, onset_min: 2, onset_max: 5, growth: linear}\n"
        "  - <<: *base\n    mode: internal_leakage\n")
    scenario = parse_scenario(text)
    a, b = scenario.degradations
    assert b.mode == "internal_leakage" and dataclasses.replace(b, mode=a.mode) == a


def test_null_lists_and_sections_take_defaults():
    text = _base_text().split("hidden_effects:")[0] + "hidden_effects:\ndrift: null\nmission:\n"
    scenario = parse_scenario(text)
    assert scenario.hidden_effects == () and scenario.drift == ()
    assert scenario.mission == schema_module.MissionSpec()


def test_safe_loader_refuses_python_objects():
    text = _base_text().replace("name: valid_base", "name: !!python/object/apply:os.system ['true']")
    with pytest.raises(ScenarioValidationError) as info:
        parse_scenario(text, source="x.yaml")
    assert info.value.problems[0].line == 3


def test_unreadable_file(tmp_path):
    with pytest.raises(ScenarioError, match=r"Cannot read the scenario file .*missing.yaml"):
        load_scenario_file(tmp_path / "missing.yaml")
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes("name: caf\xe9\n".encode("latin-1"))
    with pytest.raises(ScenarioError, match="latin1.yaml"):
        load_scenario_file(bad)


def test_round_trip_through_yaml(tmp_path):
    scenario = load_scenario("model_discrepancy")
    path = tmp_path / "model_discrepancy.yaml"
    path.write_text(yaml.safe_dump(scenario.to_dict(), sort_keys=False))
    assert load_scenario(path) == scenario
    assert load_scenario(str(path)) == scenario


def test_a_file_must_declare_its_own_name(tmp_path):
    """An edited copy saved under another name must not keep the original's id; every file is checked."""
    text = (Path(__file__).parents[1] / "scenarios" / "paper_2012.yaml").read_text()
    for stem, suffix in (("mine", ".yaml"), ("mine", ".yml"), ("My-Copy", ".yaml")):
        path = tmp_path / f"{stem}{suffix}"
        path.write_text(text)
        with pytest.raises(ScenarioValidationError) as info:
            load_scenario(path)
        (problem,) = info.value.problems
        assert (problem.field, problem.line, problem.given) == ("name", 5, "'paper_2012'")
        assert f"'{stem}'" in problem.allowed and "rename the file to paper_2012.yaml" in problem.hint.lower()
        assert str(info.value).startswith(f"{path}:5: name must be '{stem}', the file's name")
    merged = tmp_path / "merged.yaml"  # the name comes from a merge key: still checked
    merged.write_text("base: &b\n  name: paper_2012\n" + text.replace("name: paper_2012", "<<: *b"))
    with pytest.raises(ScenarioValidationError, match="name must be 'merged', the file's name"):
        load_scenario(merged)
    (tmp_path / "mine.yaml").write_text(text.replace("name: paper_2012 ", "name: mine "))
    assert load_scenario(tmp_path / "mine.yaml").id == "mine-v3"
    assert parse_scenario(text, "mine.yaml").name == "paper_2012"  # text without a file: no file name to match


def test_physics_error_in_mission_is_located(monkeypatch):
    """A ParameterError raised by MissionProfile itself becomes a located ScenarioError on the mapped field."""

    class StrictProfile(schema_module.MissionProfile):
        def __post_init__(self):
            super().__post_init__()
            if self.duration_s > 1200.0:
                raise ParameterError(f"The 'MissionProfile.duration_s' parameter must be <= 1200. "
                                     f"Got {self.duration_s!r} instead.")

    monkeypatch.setattr(schema_module, "MissionProfile", StrictProfile)
    text = _base_text().replace("sensor:\n", "mission:\n  duration_min: 25.0\nsensor:\n")
    with pytest.raises(ScenarioValidationError) as info:
        parse_scenario(text, source="x.yaml")
    (problem,) = info.value.problems
    assert (problem.field, problem.line, problem.given) == ("mission.duration_min", 15, "25.0")
    assert "MissionProfile.duration_s is <= 1200 (got 1500.0)" in problem.allowed


def test_python_construction_names_the_class():
    with pytest.raises(ScenarioValidationError) as info:
        schema_module.DegradationSpec(mode="backlash", probability=0.5, onset_min=3, onset_max=1, growth="step")
    assert str(info.value) == "DegradationSpec.onset_max must be >= onset_min (3). Got 1 instead."
    assert isinstance(info.value, ScenarioError)


def test_scenario_is_frozen_and_hashable():
    scenario = load_scenario_file(VALID_BASE)
    with pytest.raises(dataclasses.FrozenInstanceError):
        scenario.name = "other"  # type: ignore[misc]
    assert hash(scenario) == hash(load_scenario_file(VALID_BASE))
    assert isinstance(scenario, Scenario)
