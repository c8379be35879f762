"""The raw-signal baseline and the raw-flight input (RawFlight, needs_raw)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from fuelhm_baselines.raw_tracking import FEATURES, RawTrackingMethod, raw_features
from fuelhm_bench.errors import DataFormatError, MethodError
from fuelhm_bench.flights.fleet import FleetConfig, flights_frame, iter_flights
from fuelhm_bench.flights.schedule import ModeSchedule
from fuelhm_bench.methods.raw import RAW_SIGNALS, RawFlight, iter_raw_flights
from fuelhm_bench.scenarios import load_scenario


def _fleet(n_units, n_flights, schedules=(), seed=0):
    cfg = load_scenario("paper_2012").training_fleet_config()
    return dataclasses.replace(cfg, n_units=n_units, n_flights=n_flights, schedules=schedules,
                               seed=seed, mission=dataclasses.replace(cfg.mission, duration_s=120.0))


def _raw(config):
    out = []
    for batch in iter_flights(config):
        frame = flights_frame(batch)
        frame["flight_index"] = frame["flight_id"].map({f.flight_id: f.flight_index for f in batch})
        out.extend(iter_raw_flights(frame))
    return out


@pytest.fixture(scope="module")
def flights():
    healthy = _raw(_fleet(4, 3, seed=1))
    test_healthy = _raw(_fleet(1, 3, seed=2))
    leak = ModeSchedule("null_bias_drift", growth="step", ramp_flights=1, max_intensity=1.0)
    faulty = _raw(_fleet(1, 3, (leak,), seed=2))
    return healthy, test_healthy, faulty


def test_features_worked_values():
    t = np.arange(0, 10, 0.01)
    i = np.sin(t)
    x = 2.0 * (1 - np.cos(t))
    f = raw_features(RawFlight(0, 0, t, i, x, x - 0.1, np.full_like(t, 80.0)))
    assert f.shape == (len(FEATURES),)
    assert f[0] == pytest.approx(0.1) and f[1] == pytest.approx(0.1)
    assert f[3] == pytest.approx(2.0, rel=1e-3) and f[4] < 1e-2


def test_raw_method_separates_a_degraded_unit(flights):
    """A unit whose null bias drifted fully (physics v2: the 100 % leak is a small 7 cm3/s, see docs/physics.md §6)."""
    healthy, test_healthy, faulty = flights
    from fuelhm_bench.methods.checks import make_check_data

    table = make_check_data(0).healthy  # indicator table is not used by this method
    m = RawTrackingMethod(random_state=0).fit(table, raw_flights=iter(healthy))
    assert len(m.calibration_scores_) == 3  # one whole unit (3 flights) held out
    m.start_unit(0)
    ok = [m.decide({"unit_id": 0, "flight_index": f.flight_index}, raw=f) for f in test_healthy]
    m.start_unit(0)
    bad = [m.decide({"unit_id": 0, "flight_index": f.flight_index}, raw=f) for f in faulty]
    assert min(d.score for d in bad) > max(d.score for d in ok)  # every degraded flight above every healthy one
    assert all(d.alarm for d in bad) and not any(d.alarm for d in ok)


def test_needs_raw_is_enforced(flights):
    from fuelhm_bench.methods.checks import make_check_data

    table = make_check_data(0).healthy
    with pytest.raises(MethodError, match="needs the raw healthy training flights"):
        RawTrackingMethod().fit(table)
    m = RawTrackingMethod(random_state=0).fit(table, raw_flights=flights[0])
    m.start_unit(0)
    with pytest.raises(MethodError, match=r"needs the raw flight .*decide\(row, raw=RawFlight\)"):
        m.decide({"unit_id": 0, "flight_index": 0})


def test_raw_flight_validation():
    t = np.arange(5.0)
    good = {k: t.copy() for k in RAW_SIGNALS}
    RawFlight(0, 0, **good)
    with pytest.raises(DataFormatError, match="'position_mm' field of RawFlight must be a 1-D"):
        RawFlight(0, 0, **{**good, "position_mm": t[:3]})
    with pytest.raises(DataFormatError, match="'current_mA' field of RawFlight must be finite"):
        RawFlight(0, 0, **{**good, "current_mA": np.r_[t[:4], np.nan]})
    with pytest.raises(DataFormatError, match="strictly increasing"):
        RawFlight(0, 0, **{**good, "time_s": t[::-1]})
    with pytest.raises(DataFormatError, match="Missing"):
        list(iter_raw_flights(pd.DataFrame({"unit_id": [0]})))
