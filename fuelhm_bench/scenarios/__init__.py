"""Benchmark scenarios: a versioned schema, validated YAML loading, shipped scenarios.

A :class:`Scenario` (``schema_version: 1``) is a tree of frozen dataclasses
that says everything a run needs; YAML is only its storage. Load one with
:func:`load_scenario` (a shipped name such as ``"all_modes"`` or
``"all_modes-v1"``, or a file path); turn it into simulator inputs with
:meth:`Scenario.training_fleet_config` and :meth:`Scenario.test_fleet_config`.
Every validation error is a :class:`~fuelhm_bench.errors.ScenarioError`
naming the file, the line, the field path, what is allowed and the value given.

Examples
--------
>>> from fuelhm_bench.scenarios import list_scenarios, load_scenario
>>> scenario = load_scenario("paper_2012")
>>> [d.mode for d in scenario.degradations]
['null_bias_drift', 'internal_leakage']
>>> config = scenario.test_fleet_config()  # a fuelhm_bench.flights.fleet.FleetConfig
"""

from fuelhm_bench.scenarios._fields import Problem, ScenarioValidationError
from fuelhm_bench.scenarios.jsonschema import scenario_json_schema
from fuelhm_bench.scenarios.loader import load_scenario_file, parse_scenario
from fuelhm_bench.scenarios.registry import list_scenarios, load_scenario, shipped_scenario_files
from fuelhm_bench.scenarios.schema import (
    DEFAULT_RUN_BUDGET_FLIGHT_HOURS,
    DRIFT_CHANGES,
    FIDELITIES,
    MAX_DURATION_MIN,
    MAX_SEED,
    MAX_FLIGHTS_PER_UNIT,
    MAX_UNITS,
    RUN_BUDGET_ENV,
    SUPPORTED_SCHEMA_VERSIONS,
    CostSpec,
    DegradationSpec,
    DriftSpec,
    FleetSpec,
    HiddenEffectSpec,
    MissionSpec,
    OperatingSpec,
    RunCost,
    Scenario,
    SeedSpec,
    SensorSpec,
    TrainingSpec,
    drift_parameter_paths,
    drift_range,
    run_budget,
)

__all__ = [
    "CostSpec", "DEFAULT_RUN_BUDGET_FLIGHT_HOURS", "DRIFT_CHANGES", "DegradationSpec", "DriftSpec", "FIDELITIES", "FleetSpec", "HiddenEffectSpec",
    "MAX_DURATION_MIN", "MAX_SEED", "MAX_FLIGHTS_PER_UNIT", "MAX_UNITS", "MissionSpec", "OperatingSpec", "Problem", "RUN_BUDGET_ENV", "RunCost", "SUPPORTED_SCHEMA_VERSIONS", "Scenario", "ScenarioValidationError",
    "SeedSpec", "SensorSpec", "TrainingSpec", "drift_parameter_paths", "drift_range", "run_budget", "list_scenarios", "load_scenario",
    "load_scenario_file", "parse_scenario", "scenario_json_schema", "shipped_scenario_files",
]
