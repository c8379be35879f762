"""Tests of the scenario dataclasses and their rules (fuelhm_bench.scenarios.schema)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from fuelhm_bench.errors import ScenarioError
from fuelhm_bench.physics.degradations import LAWS
from fuelhm_bench.scenarios import (
    CostSpec,
    DegradationSpec,
    DriftSpec,
    FleetSpec,
    HiddenEffectSpec,
    MissionSpec,
    Scenario,
    ScenarioValidationError,
    SeedSpec,
    SensorSpec,
    TrainingSpec,
    drift_parameter_paths,
    drift_range,
    load_scenario_file,
)

BASE = load_scenario_file(Path(__file__).parent / "data" / "scenarios_broken" / "valid_base.yaml")


def deg(mode: str, p: float, **kw) -> DegradationSpec:
    return DegradationSpec(mode=mode, probability=p, onset_min=kw.pop("onset_min", 1), onset_max=kw.pop("onset_max", 3),
                           growth=kw.pop("growth", "linear"), **kw)


def problems(**changes) -> list[tuple[str, str]]:
    """``(field, message)`` of the problems of BASE with ``changes``; [] if valid."""
    try:
        dataclasses.replace(BASE, **changes)
    except ScenarioValidationError as exc:
        return [(p.field, p.message("Scenario")) for p in exc.problems]
    return []


def test_minimal_scenario_in_python():
    s = Scenario(schema_version=1, name="mini", version=1, description="Tiny.",
                 fleet=FleetSpec(units=1, flights_per_unit=1), training=TrainingSpec(units=2, flights_per_unit=1),
                 seeds=SeedSpec(master=0))
    assert s.degradations == () and s.simultaneous and s.fidelity == "physics"
    assert s.test_fleet_config().schedules == ()
    assert s.costs == CostSpec() and s.mission == MissionSpec()


def test_fields_are_keyword_only_and_normalised():
    with pytest.raises(TypeError):
        FleetSpec(3, 4)  # type: ignore[misc]
    spec = FleetSpec(units=3, flights_per_unit=4, dispersion_scale=2)
    assert isinstance(spec.dispersion_scale, float)
    s = dataclasses.replace(BASE, degradations=list(BASE.degradations))
    assert isinstance(s.degradations, tuple)


@pytest.mark.parametrize("cls, kwargs, field, allowed", [
    (FleetSpec, {"units": True, "flights_per_unit": 3}, "units", "an integer in [1, 10000]"),
    (TrainingSpec, {"units": 1, "flights_per_unit": 3}, "units", "an integer in [2, 10000]"),  # fit != calibration
    (FleetSpec, {"units": 2, "flights_per_unit": 3.0}, "flights_per_unit", "an integer in [1, 10000]"),
    (FleetSpec, {"units": 2, "flights_per_unit": 3, "dispersion_scale": float("nan")}, "dispersion_scale",
     "a number in [0, 3]"),
    (FleetSpec, {"units": 2, "flights_per_unit": 3, "dispersion_scale": 5}, "dispersion_scale",
     "a number in [0, 3]"),  # passed, then manufacture failed: "spool_friction_n must be >= 0" (seed-dependent)
    (SensorSpec, {"noise_std_um": -1.0}, "noise_std_um", "a number in [0, 10000]"),
    (SensorSpec, {"noise_std_um": 2e4}, "noise_std_um", "a number in [0, 10000]"),  # 1e9 passed validate
    (MissionSpec, {"test_sweep": "yes"}, "test_sweep", "true or false"),
    (MissionSpec, {"duration_min": 1.5}, "duration_min", ">= (start_duration_s + 60 s) / 60 = 2 min"),
    (MissionSpec, {"sweep_low_mm": 40.0, "sweep_high_mm": 30.0}, "sweep_high_mm", "> sweep_low_mm (40 mm)"),
    (DegradationSpec, {"mode": "backlash", "probability": 0.5, "onset_min": 0, "onset_max": 1, "growth": "step",
                       "max_intensity": 0.0}, "max_intensity", "a number in (0, 1]"),
    (DriftSpec, {"parameter": "fluid.density_kg_m3", "change": "relative", "value": -1.0}, "value",
     "> -1 for a relative change"),
    (DriftSpec, {"parameter": "fluid.density_kg_m3", "change": "percent", "value": 1.0}, "change",
     "one of relative, absolute"),
    (CostSpec, {"detectable_fraction": 0.5, "failure_fraction": 0.5}, "failure_fraction",
     "> detectable_fraction (0.5)"),
    (Scenario, {}, None, None),
])
def test_field_validation(cls, kwargs, field, allowed):
    if field is None:  # required fields: Python itself refuses
        with pytest.raises(TypeError):
            cls(**kwargs)
        return
    with pytest.raises(ScenarioValidationError) as info:
        cls(**kwargs)
    (problem,) = info.value.problems
    assert problem.field == field and allowed in problem.allowed
    assert str(info.value).startswith(f"{cls.__name__}.{field} must be")


def test_every_unit_the_dispersion_can_manufacture_is_valid():
    """The dispersion's worst case (draws at their 3-sd truncation) is checked against the fleets' models: a drift
    to a discharge coefficient of 0.98 (<= 1) passed validate, then manufacture failed at a random unit."""
    assert problems(fleet=dataclasses.replace(BASE.fleet, dispersion_scale=3.0)) == []  # the most the nominal allows
    drift = (DriftSpec(parameter="servovalve.discharge_coefficient", change="relative", value=0.4),)
    ((field, message),) = problems(drift=drift)
    assert field == "fleet.dispersion_scale"
    assert message.startswith("Scenario.fleet.dispersion_scale must be in [0, 0.339] here: every unit it can "
                              "manufacture must be a valid model. Got 1.0 instead.")
    assert "discharge_coefficient must be in (0, 1] and would reach 1.0388 in the drifted scored fleet" in message
    assert problems(drift=drift, fleet=dataclasses.replace(BASE.fleet, dispersion_scale=0.339)) == []


def test_every_cost_is_bounded():
    """failure_kusd: 1e308 passed, then the run's cost_kusd overflowed to inf; one bound for every cost."""
    from fuelhm_bench.scenarios.schema import MAX_COST_KUSD

    costs = [f.name for f in dataclasses.fields(CostSpec) if f.name.endswith("_kusd")]
    assert costs == ["false_alarm_kusd", "undetected_flight_kusd", "failure_kusd", "repair_kusd"]
    for name in costs:
        assert getattr(CostSpec(**{name: MAX_COST_KUSD}), name) == 1e6
        for value in (1e308, 1.000001e6):
            with pytest.raises(ScenarioValidationError) as info:
                CostSpec(**{name: value})
            (problem,) = info.value.problems
            assert problem.field == name and problem.allowed == "a number in [0, 1000000]"


def test_probabilities_rule_when_not_simultaneous():
    ok = (deg("backlash", 0.2), deg("spool_friction", 0.3))
    assert problems(degradations=ok, healthy_probability=0.5) == []
    (p,) = problems(degradations=ok, healthy_probability=0.6)
    assert p[0] == "healthy_probability" and "0.2 + 0.3 + 0.6 = 1.1" in p[1] and "0.5 would" in p[1]
    (p,) = problems(degradations=(deg("backlash", 0.7), deg("spool_friction", 0.6)), healthy_probability=0.0)
    assert "alone sum to 1.3 > 1" in p[1]
    (p,) = problems(healthy_probability=None)
    assert p[0] == "healthy_probability" and "given when simultaneous is false" in p[1]
    # Decimal rounding (7 x 0.1 + 0.3) is not an error.
    modes = ("filter_contamination", "null_bias_drift", "backlash", "spool_friction", "radial_clearance",
             "internal_leakage", "diaphragm_clogging")
    assert problems(degradations=tuple(deg(m, 0.1) for m in modes), healthy_probability=0.3) == []


def test_healthy_probability_is_omitted_when_simultaneous():
    (p,) = problems(simultaneous=True)
    assert p[0] == "healthy_probability" and "omitted when simultaneous is true" in p[1]
    assert problems(simultaneous=True, healthy_probability=None) == []


def test_schedule_rules():
    (p,) = problems(degradations=(deg("backlash", 0.25), deg("backlash", 0.25)))
    assert p[0] == "degradations[1].mode" and "degradations[0] is backlash" in p[1]
    (p,) = problems(degradations=(deg("backlash", 0.25, onset_max=10), deg("internal_leakage", 0.25)))
    assert p[0] == "degradations[0].onset_max" and "flights_per_unit - 1 = 9" in p[1]
    assert problems(degradations=(deg("backlash", 0.25, onset_min=9, onset_max=9), deg("internal_leakage", 0.25))) == []


def test_drift_rules():
    drift = lambda path, change="relative", value=0.1: DriftSpec(parameter=path, change=change, value=value)  # noqa: E731
    law = LAWS["internal_leakage"]
    (p,) = problems(drift=(drift(f"{law.component}.{law.parameter}", "absolute", 1e-12),))
    assert "degradation mode internal_leakage acts on it" in p[1]
    (p,) = problems(drift=(drift("controller.frame_s"),))
    assert "set by mission.frame_rate_hz" in p[1]
    (p,) = problems(drift=(drift("servovalve.lap_m"),))
    assert p[0] == "drift[0].change" and "nominal value is 0" in p[1]
    assert problems(drift=(drift("servovalve.lap_m", "absolute", 2e-6),)) == []
    (p,) = problems(drift=(drift("fluid.density_kg_m3"), drift("fluid.density_kg_m3")))
    assert p[0] == "drift[1].parameter" and "not already drifted (drift[0])" in p[1]
    (p,) = problems(drift=(drift("servo.lap_m"),))
    assert "component one of fluid, servovalve" in p[1]
    # Effect parameters may drift only when the effect is a hidden effect.
    (p,) = problems(drift=(drift("effect.lvdt_lag.time_constant_s"),))
    assert "add lvdt_lag to hidden_effects first" in p[1]
    with_lag = BASE.hidden_effects + (HiddenEffectSpec(effect="lvdt_lag"),)
    s = dataclasses.replace(BASE, hidden_effects=with_lag, drift=(drift("effect.lvdt_lag.time_constant_s", value=0.5),))
    assert math.isclose(s.test_fleet_config().nominal.get("effect.lvdt_lag.time_constant_s"), 0.03)
    assert s.training_fleet_config().nominal.get("effect.lvdt_lag.time_constant_s") == 0.02


def test_drift_stays_a_population_shift():
    """A relative drift of 1e9 and an absolute one of 1e20 on a parameter bounded only below, and the full
    null-bias fault as a drift of the static null bias, were all valid."""
    drift = lambda path, change, value: DriftSpec(parameter=path, change=change, value=value)  # noqa: E731
    (p,) = problems(drift=(drift("fluid.supply_rise_at_100pct_pa", "relative", 1e9),))
    assert p[0] == "drift[0].value"
    assert p[1].startswith("Scenario.drift[0].value must be in [-0.5, 1] (relative drift of "
                           "fluid.supply_rise_at_100pct_pa), to keep it within a factor 2 of its nominal value 1.03e+07")
    assert p[1].endswith("Got 1000000000.0 instead. It would set fluid.supply_rise_at_100pct_pa from 1.03e+07 to "
                         "1.03e+16.")
    (p,) = problems(drift=(drift("fluid.supply_rise_at_100pct_pa", "absolute", 1e20),))
    assert "must be in [-5.15e+06, 1.03e+07] (absolute drift" in p[1]
    (p,) = problems(drift=(drift("servovalve.null_bias_a", "absolute", LAWS["null_bias_drift"].delta),))
    assert "must be in [-0.00025, 0.0004] (absolute drift of servovalve.null_bias_a)" in p[1]
    assert "it adds to servovalve.null_bias_drift_a, so a larger drift is the null_bias_drift fault" in p[1]
    (p,) = problems(drift=(drift("driver.offset_a", "absolute", -1e-3),))
    assert "must be in [-0.0004, 0.0004] (absolute drift of driver.offset_a)" in p[1]
    # The bounds themselves are allowed, and so are the shipped robustness_drift's drifts.
    assert problems(drift=(drift("fluid.supply_rise_at_100pct_pa", "relative", -0.5),
                           drift("servovalve.null_bias_a", "absolute", 4e-4),
                           drift("servovalve.spool_time_constant_s", "relative", 1.0))) == []
    assert drift_range("fluid.density_kg_m3", 800.0)[:2] == (400.0, 1600.0)
    assert drift_range("servovalve.lap_m", 0.0)[:2] == (-math.inf, math.inf)  # the physics bounds it


def test_drift_paths_exclude_degradation_parameters():
    paths = drift_parameter_paths()
    assert "servovalve.spool_time_constant_s" in paths
    for law in LAWS.values():
        assert f"{law.component}.{law.parameter}" not in paths
    assert "effect.rod_friction.coulomb_n" in drift_parameter_paths(["rod_friction"])


def test_drift_is_applied_in_order():
    d1 = DriftSpec(parameter="load.aero_force_at_100pct_n", change="absolute", value=100.0)
    d2 = DriftSpec(parameter="load.aero_force_at_100pct_n", change="relative", value=0.5)
    s = dataclasses.replace(BASE, drift=(d1,))
    nominal = s.truth_model().get("load.aero_force_at_100pct_n")
    assert s.drifted_model().get("load.aero_force_at_100pct_n") == nominal + 100.0
    assert d2.apply(d1.apply(s.truth_model())).get("load.aero_force_at_100pct_n") == (nominal + 100.0) * 1.5


def test_hidden_effect_rules():
    (p,) = problems(hidden_effects=(HiddenEffectSpec(effect="lvdt_lag"), HiddenEffectSpec(effect="lvdt_lag")))
    assert p[0] == "hidden_effects[1].effect" and "hidden_effects[0] is lvdt_lag" in p[1]
    spec = HiddenEffectSpec(effect="rod_friction", parameters={"coulomb_n": 90})
    assert spec.parameters == (("coulomb_n", 90.0),) and spec.build().coulomb_n == 90.0


def test_seeds():
    seeds = SeedSpec(master=5)
    assert seeds.training_seed != seeds.test_seed
    assert seeds.training_seed == SeedSpec(master=5).training_seed  # deterministic
    assert seeds.training_seed == int(np.random.SeedSequence([5, 1]).generate_state(1)[0])
    assert SeedSpec(master=5, training=3, test=4).test_seed == 4
    with pytest.raises(ScenarioValidationError, match="different from the training seed"):
        SeedSpec(master=0, training=7, test=7)
    s = dataclasses.replace(BASE, seeds=SeedSpec(master=1, training=11, test=12))
    assert (s.training_fleet_config().seed, s.test_fleet_config().seed) == (11, 12)


def test_mission_and_operating_reach_the_profile():
    s = dataclasses.replace(BASE, mission=MissionSpec(duration_min=3.0, frame_rate_hz=50.0, test_sweep=False,
                                                      sweep_rates_mm_s=(20, 40)))
    profile = s.mission_profile()
    assert (profile.duration_s, profile.frame_s, profile.test_sweep) == (180.0, 0.02, False)
    assert profile.sweep_rates_m_s == (0.02, 0.04)
    assert s.test_fleet_config().nominal.controller.frame_s == 0.02
    assert profile.throttle_step_std == BASE.operating.throttle_step_std


def test_to_dict_round_trip_in_python():
    d = BASE.to_dict()
    assert list(d) == [f.name for f in dataclasses.fields(Scenario)]
    assert d["hidden_effects"] == [{"effect": "rod_friction", "parameters": {"coulomb_n": 150.0}}]
    assert isinstance(BASE.degradations[0].schedule().growth, str)


def test_errors_are_scenario_errors():
    with pytest.raises(ScenarioError):
        dataclasses.replace(BASE, fidelity="quantum")


@pytest.mark.parametrize("old, new, match", [
    ("sweep_high_mm: 57.0", "sweep_high_mm: 500.0", r":\d+: mission.sweep_high_mm must be < the model's stroke "
                                                   r"\(60 mm\)"),
    ("frame_rate_hz: 100.0", "frame_rate_hz: 7.0", r":\d+: mission.frame_rate_hz must be a number in \[20, 10000\]"),
])
def test_scenarios_that_could_not_produce_indicators_are_refused(tmp_path, old, new, match):
    """Both validated before, then failed in evaluate with "HealthyModel needs at least 11 healthy flights"
    (no valid indicator: the rod held on its end stop; no idle samples at 7 Hz), naming neither file nor field."""
    from fuelhm_bench.scenarios import load_scenario
    from fuelhm_bench.scenarios.registry import shipped_scenario_files

    text = shipped_scenario_files()["paper_2012"].read_text()
    assert old in text
    path = tmp_path / "paper_2012.yaml"
    path.write_text(text.replace(old, new))
    with pytest.raises(ScenarioError, match=match):
        load_scenario(path)
