"""Recalibration (paper section IV.B, Fig. 7): replay, differentiator, parameter recovery, CLI."""

from __future__ import annotations

import numpy as np
import pytest

from fuelhm_bench.calibration import replay as rp
from fuelhm_bench.calibration import velocity as vel
from fuelhm_bench.calibration.recalibrate import RECALIBRATION_PARAMETERS, CalibrationConfig, recalibrate
from fuelhm_bench.calibration.synthetic import hidden_effect_flights
from fuelhm_bench.cli import main
from fuelhm_bench.errors import DataFormatError
from fuelhm_bench.flights.fleet import FleetConfig, flights_frame, iter_flights
from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.io import FlightArrays, split_flights, write_flights
from fuelhm_bench.physics.model import Dispersion, LoopModel, load_model

#: The perturbed "true" unit of the recovery test: a few % off nominal on every fitted parameter.
TRUE_VALUES = {
    "servovalve.null_bias_a": 5e-4 + 2e-4,
    "servovalve.slot_width_null_m": 2e-3 * 1.04,
    "servovalve.slot_width_outer_m": 4e-3 * 0.96,
    "servovalve.transition_start": 0.19 * 1.05,
    "servovalve.transition_end": 0.31 * 0.96,
    "cylinder.diaphragm_diameter_m": 3e-4 * 1.06,
    "load.aero_force_at_100pct_n": 600.0,
    "servovalve.rated_current_a": 8e-3 * 1.03,
}
#: Recovery tolerance per parameter: relative, except absolute for the null bias [A],
#: the transitions [-] and the load [N].
TOLERANCE = {
    "servovalve.null_bias_a": ("abs", 1e-5),
    "servovalve.slot_width_null_m": ("rel", 0.01),
    "servovalve.slot_width_outer_m": ("rel", 0.01),
    "servovalve.transition_start": ("abs", 0.006),
    "servovalve.transition_end": ("abs", 0.006),
    "cylinder.diaphragm_diameter_m": ("rel", 0.01),
    "load.aero_force_at_100pct_n": ("abs", 20.0),
    "servovalve.rated_current_a": ("rel", 0.01),
}


def _flights(model: LoopModel, *, n_flights: int = 3, minutes: float = 3.0, seed: int = 5):
    config = FleetConfig(n_units=1, n_flights=n_flights, mission=MissionProfile(duration_s=60.0 * minutes),
                         nominal=model, dispersion=Dispersion(scale=0.0), seed=seed)
    frame = flights_frame([f for batch in iter_flights(config) for f in batch])
    flights, rejected = split_flights(frame)
    assert not rejected
    return frame, flights


@pytest.fixture(scope="module")
def perturbed():
    frame, flights = _flights(LoopModel().with_parameters(TRUE_VALUES))
    return frame, flights, recalibrate(flights)


def test_window_weights_are_the_least_squares_slope():
    assert np.allclose(vel.window_weights(2), [0.2, 0.3, 0.3, 0.2])
    for h in (1, 2, 4):
        w = vel.window_weights(h)
        assert w.sum() == pytest.approx(1.0)
        t = np.arange(30) * 0.01
        x = 3.0 + 2.5 * t + 4.0 * t ** 2  # exact for a quadratic at the centre sample
        v = vel.windowed(vel.frame_rates(x, 0.01), h)
        assert np.allclose(v[h:-h], 2.5 + 8.0 * t[h:-h])
        assert np.isnan(v[:h]).all() and np.isnan(v[-h:]).all()


@pytest.mark.parametrize("effect", [None, "lvdt_lag"])
def test_replay_of_the_same_model_reproduces_the_measured_velocity(effect):
    model = LoopModel().with_parameters({"lvdt.noise_std_m": 0.0, "lvdt.adc_bits": 0})
    if effect:
        model = model.with_effect(effect, time_constant_s=0.03)
    _, flights = _flights(model, n_flights=1, minutes=2.0)
    rs = rp.prepare_replay(flights)
    same = rp.residuals(model, rs)
    assert rs.n_scored > 5000
    # Only the memory of the spool friction dead zone across segment junctions differs.
    assert np.sqrt(np.mean(same ** 2)) < 0.05
    if effect:  # the model without the sensor lag does not reproduce it
        other = rp.residuals(model.without_effect(effect), rs)
        assert np.sqrt(np.mean(other ** 2)) > 20 * np.sqrt(np.mean(same ** 2))


def test_recalibration_recovers_perturbed_parameters(perturbed):
    _, _, result = perturbed
    values = {e.path: e.value for e in result.estimates}
    assert set(values) == {p.path for p in RECALIBRATION_PARAMETERS}
    for path, truth in TRUE_VALUES.items():
        kind, tol = TOLERANCE[path]
        err = abs(values[path] - truth) / (abs(truth) if kind == "rel" else 1.0)
        assert err < tol, f"{path}: fitted {values[path]:.6g}, true {truth:.6g}"


def test_recalibration_shrinks_the_gap(perturbed):
    _, _, result = perturbed
    assert result.gap_before > 0.5
    assert result.gap_after < 0.1 * result.gap_before
    assert result.gap_after < 0.1  # mm/s: the noise floor of 3 short flights
    assert result.rms_after < result.rms_before


def test_identifiability_of_the_subset_is_reported(perturbed):
    _, _, result = perturbed
    (idf,) = result.identifiability.values()
    assert idf.names == tuple(p.path for p in RECALIBRATION_PARAMETERS)
    assert 1.0 <= idf.condition < 100.0
    assert idf.max_abs_correlation < 0.98
    assert np.all(idf.sensitivity > 0.01)  # every parameter moves the residuals by > 0.01 mm/s per dispersion


def test_recalibration_without_transients_is_refused():
    t = np.arange(20000) * 0.01
    rng = np.random.default_rng(0)
    flight = FlightArrays(1, None, t, 0.3 + 0.002 * rng.standard_normal(t.size),
                          30.0 + 0.017 * np.round(rng.standard_normal(t.size)))
    with pytest.raises(DataFormatError, match="Not enough excitation"):
        recalibrate([flight], config=CalibrationConfig())


def test_calibrate_command_names_the_file_without_excitation(tmp_path, capsys):
    """Was 'Not enough excitation in the flights of the flights: ...', the file not named."""
    sweep = tmp_path / "short_sweep.parquet"
    assert main(["sweep", "--ramp-seconds", "1", "--out", str(sweep)]) == 0
    assert main(["calibrate", str(sweep), "--out", str(tmp_path / "m.yaml")]) == 2
    err = capsys.readouterr().err
    assert f"error: {sweep}: Not enough excitation in the flights: " in err and "of the flights" not in err
    assert not (tmp_path / "m.yaml").exists()


def test_calibrate_command_writes_a_loadable_model_and_a_plot(perturbed, tmp_path, capsys):
    frame, _, result = perturbed
    data = write_flights(frame, tmp_path / "measured.parquet")
    out, plot = tmp_path / "calibrated.yaml", tmp_path / "fig7.png"
    assert main(["calibrate", str(data), "--out", str(out), "--plot", str(plot)]) == 0
    text = capsys.readouterr().out
    assert "gap" in text and "servovalve.null_bias_a" in text
    model = load_model(out)
    for path, truth in TRUE_VALUES.items():
        kind, tol = TOLERANCE[path]
        assert abs(model.get(path) - truth) / (abs(truth) if kind == "rel" else 1.0) < tol
    assert plot.stat().st_size > 10000
    sim = tmp_path / "sim.parquet"
    assert main(["simulate", "--model", str(out), "--units", "1", "--flights", "1", "--minutes", "2",
                 "--out", str(sim)]) == 0
    # Refuses to overwrite without --force, accepts with it.
    assert main(["calibrate", str(data), "--out", str(out)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert main(["calibrate", str(data), "--out", str(out), "--force"]) == 0


def test_calibrate_command_reports_bad_inputs(tmp_path, capsys):
    frame, _ = hidden_effect_flights(None, n_units=1, n_flights=1, minutes=2.0, seed=1)
    bad = tmp_path / "bad.csv"
    frame.rename(columns={"position_mm": "pos"}).to_csv(bad, index=False)
    assert main(["calibrate", str(bad), "--out", str(tmp_path / "m.yaml")]) == 2
    err = capsys.readouterr().err
    assert "missing the required column" in err and "position_mm" in err
    good = write_flights(frame, tmp_path / "good.parquet")
    broken = tmp_path / "broken.yaml"
    broken.write_text("servovalve:\n  null_bias_a: [1, 2\n")
    assert main(["calibrate", str(good), "--model", str(broken), "--out", str(tmp_path / "m.yaml")]) == 2
    err = capsys.readouterr().err
    assert "broken.yaml" in err and "not valid YAML" in err
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text("servovalve:\n  null_bias: 0.0005\n")
    assert main(["calibrate", str(good), "--model", str(unknown), "--out", str(tmp_path / "m.yaml")]) == 2
    assert "unknown parameter 'servovalve.null_bias'" in capsys.readouterr().err


def test_replay_splits_flights_at_time_gaps():
    model = LoopModel().with_parameters({"lvdt.noise_std_m": 0.0, "lvdt.adc_bits": 0})
    frame, _ = _flights(model, n_flights=1, minutes=2.0)
    keep = ~frame["time_s"].between(70.0, 75.0)  # a 5 s hole in the recording
    flights, _ = split_flights(frame[keep])
    rs = rp.prepare_replay(flights)
    residual = rp.residuals(model, rs)
    assert np.sqrt(np.mean(residual ** 2)) < 0.05  # no segment integrates across the hole
    with pytest.raises(DataFormatError, match="sampled every"):  # two sample rates in one replay
        slow = FlightArrays(9, None, np.arange(100) * 0.02, np.zeros(100) + np.arange(100) % 2, np.zeros(100))
        rp.prepare_replay(flights + [slow])


def test_replay_of_jittered_timestamps_says_how_irregular_the_sampling_is():
    frame, _ = _flights(LoopModel(), n_flights=1, minutes=2.0)
    jittered = frame.copy()
    jittered["time_s"] += np.random.default_rng(0).uniform(-0.1, 0.1, len(frame)) * 0.01  # +/- 10 % of the frame
    flights, _ = split_flights(jittered)
    with pytest.raises(DataFormatError, match=r"% of the intervals between samples differ from the frame .* "
                                              r"by more than 5 % \(ReplayConfig.frame_tolerance\)") as err:
        rp.prepare_replay(flights)
    assert "resample the flights onto a uniform time base" in str(err.value)
    small = frame.copy()  # within the tolerance: scored as uniform
    small["time_s"] += np.random.default_rng(0).uniform(-0.01, 0.01, len(frame)) * 0.01
    assert rp.prepare_replay(split_flights(small)[0]).n_scored > 1000


def test_replay_of_a_run_shorter_than_the_end_stop_dilation():
    # A 10-sample run at the end stop, a gap, then a normal run: the stop mask keeps the run's length.
    t = np.concatenate([np.arange(10) * 0.01, 1.0 + np.arange(2000) * 0.01])
    pos = np.concatenate([np.zeros(10), 30.0 + 10.0 * np.sin(np.arange(2000) * 0.01)])
    cur = np.concatenate([np.full(10, -2.0), 2.0 * np.cos(np.arange(2000) * 0.01)])
    rs = rp.prepare_replay([FlightArrays(0, 0, t, cur, pos)])
    assert rs.n_scored > 1000


def test_recalibration_without_n2_uses_the_documented_constant():
    frame, _ = hidden_effect_flights(None, n_units=1, n_flights=2, minutes=3.0, seed=8)
    flights, _ = split_flights(frame.drop(columns=["n2_pct"]))
    result = recalibrate(flights, config=CalibrationConfig(fit_max_frames=16000))
    assert not result.n2_measured
    assert np.allclose(result.evaluation.n2_frac, rp.ReplayConfig().n2_default_pct / 100.0)
    assert result.gap_after < 0.5 * result.gap_before


def test_a_fit_whose_start_sits_on_a_bound_still_converges():
    # A plausible fit starts from values clipped into a narrowed band, often on its limit. scipy's
    # trust-region method takes its first radius from the start scaled by the distances to the bounds;
    # with the start 1e-9 of the interval from a bound that radius was about 1e-5, the first step tiny,
    # and the fit ended on `ftol` where it began (the LVDT lag below stayed at its 3 ms start).
    from fuelhm_bench.calibration.fit import FitParameter, fit_joint

    truth = LoopModel().with_effect("lvdt_lag", time_constant_s=0.03)
    _, flights = _flights(truth, n_flights=1, minutes=2.0)
    sets = {0: rp.prepare_replay(flights)}
    start = LoopModel().with_effect("lvdt_lag", time_constant_s=0.003)
    bias = start.servovalve.null_bias_a
    on_bound = (FitParameter("servovalve.null_bias_a", "A", 1e-4, lower=bias, upper=bias + 1e-3),)
    lag = (FitParameter("effect.lvdt_lag.time_constant_s", "s", 0.3, lower=1e-4, upper=0.5, log=True),)
    fit = fit_joint({0: start}, sets, on_bound, lag, max_iterations=12)
    assert fit.shared_values["effect.lvdt_lag.time_constant_s"] == pytest.approx(0.03, rel=0.1), fit.message
    assert fit.passes > 4
    # Inside the bounds, by a bounded inset: the band's own limit is still reachable.
    assert bias <= fit.unit_values[0]["servovalve.null_bias_a"] <= bias + 1e-3
