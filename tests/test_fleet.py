"""Fleets: schedules, growth laws, streaming with bounded memory."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.flights.fleet import FleetConfig, build_units, iter_flights
from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.flights.schedule import ModeSchedule, draw_unit_schedule

SHORT = MissionProfile(duration_s=120.0, start_duration_s=40.0)


@pytest.mark.parametrize("growth, expected", [
    ("step", [0, 0, 0.8, 0.8, 0.8, 0.8]),
    ("linear", [0, 0, 0.2, 0.4, 0.6, 0.8]),
])
def test_growth_laws(growth, expected):
    s = ModeSchedule("backlash", onset_min=2, onset_max=2, growth=growth, ramp_flights=4, max_intensity=0.8)
    assert np.allclose(s.intensity(np.arange(6), 2), expected)


def test_exponential_growth_is_incipient_then_reaches_max():
    s = ModeSchedule("backlash", growth="exponential", ramp_flights=10, max_intensity=1.0)
    f = s.intensity(np.arange(12), 0)
    assert f[0] < 0.05 and np.all(np.diff(f) >= 0) and f[9] == pytest.approx(1.0) and f[11] == 1.0


def test_onset_drawn_in_range_and_seeded():
    sched = [ModeSchedule("internal_leakage", onset_min=3, onset_max=7)]
    onsets = [draw_unit_schedule(sched, np.random.default_rng(s)).onsets[0] for s in range(200)]
    assert min(onsets) == 3 and max(onsets) == 7
    again = [draw_unit_schedule(sched, np.random.default_rng(s)).onsets[0] for s in range(200)]
    assert onsets == again


def test_exclusive_modes_and_probabilities():
    sched = [ModeSchedule("internal_leakage", probability=0.3), ModeSchedule("backlash", probability=0.3)]
    drawn = [draw_unit_schedule(sched, np.random.default_rng(s), simultaneous=False) for s in range(2000)]
    n_modes = np.array([len(u.schedules) for u in drawn])
    assert n_modes.max() == 1
    assert 0.35 < np.mean(n_modes == 0) < 0.45
    with pytest.raises(ParameterError, match="summing to <= 1"):
        draw_unit_schedule([ModeSchedule("backlash", probability=0.7)] * 2, np.random.default_rng(0), simultaneous=False)


def test_schedule_validation():
    with pytest.raises(ParameterError, match="onset_max"):
        ModeSchedule("backlash", onset_min=4, onset_max=2)
    with pytest.raises(ParameterError, match="growth"):
        ModeSchedule("backlash", growth="quadratic")
    with pytest.raises(ParameterError, match="max_intensity"):
        ModeSchedule("backlash", max_intensity=0.0)


def test_units_are_reproducible_and_independent_of_fleet_size():
    a = build_units(FleetConfig(n_units=3, mission=SHORT, seed=5))
    b = build_units(FleetConfig(n_units=5, mission=SHORT, seed=5))
    assert [u.model for u in a] == [u.model for u in b[:3]]


def _peak_bytes(n_flights: int) -> int:
    config = FleetConfig(n_units=2, n_flights=n_flights, mission=SHORT, seed=1)
    for _ in iter_flights(config, batch_size=2):  # warm up (compilation, tables)
        break
    tracemalloc.start()
    done = 0
    for batch in iter_flights(config, batch_size=2):
        done += len(batch)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert done == 2 * n_flights
    return peak


def test_fleet_streaming_memory_does_not_grow_with_flights():
    small, large = _peak_bytes(2), _peak_bytes(8)
    assert large < 1.25 * small, (small, large)


def test_leaving_out_the_fuel_temperature_changes_no_other_bit():
    """``fuel_temperature=False`` (the indicator builds) skips the temperature channel only: the
    other channels and the simulated signals are the same bytes, and a model that reads the
    temperature (viscosity_temperature) still gets it."""
    from fuelhm_bench.physics.model import LoopModel

    def flights(fuel_temperature, nominal=None):
        config = FleetConfig(n_units=2, n_flights=2, mission=SHORT, seed=11,
                             **({} if nominal is None else {"nominal": nominal}))
        return [f for b in iter_flights(config, fuel_temperature=fuel_temperature) for f in b]

    full, lean = flights(True), flights(False)
    for a, b in zip(full, lean, strict=True):
        assert "fuel_temp_degC" in a.inputs.extras and "fuel_temp_degC" not in b.inputs.extras
        for name in ("n2_pct", "phase", "demand_mm"):
            assert a.inputs.extras[name].tobytes() == b.inputs.extras[name].tobytes(), name
        assert a.inputs.demand_m.tobytes() == b.inputs.demand_m.tobytes()
        assert a.inputs.n2_frac.tobytes() == b.inputs.n2_frac.tobytes()
        for name in ("current_a", "measured_position_m", "true_position_m"):
            assert getattr(a.output, name).tobytes() == getattr(b.output, name).tobytes(), name
    viscous = LoopModel().with_effect("viscosity_temperature")
    full, lean = flights(True, viscous), flights(False, viscous)
    for a, b in zip(full, lean, strict=True):
        assert a.inputs.extras["fuel_temp_degC"].tobytes() == b.inputs.extras["fuel_temp_degC"].tobytes()
        assert a.output.measured_position_m.tobytes() == b.output.measured_position_m.tobytes()


def test_recorded_n2_is_one_hundred_times_the_simulated_n2_bit_for_bit():
    """as_flight_arrays hands on the mission's recorded ``n2_pct`` channel rather than multiplying again:
    it must be exactly ``100 * n2_frac``, or the indicator tables would change."""
    config = FleetConfig(n_units=1, n_flights=2, mission=SHORT, seed=5)
    for flight in next(iter(iter_flights(config))):
        recorded = flight.as_flight_arrays().extras["n2_pct"]
        assert recorded.tobytes() == (100.0 * flight.inputs.n2_frac).tobytes()
