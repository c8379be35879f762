"""The model-discrepancy workflow on data with a hidden effect (issue 6)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.calibration.discrepancy import (
    CandidateOutcome,
    DiscrepancyConfig,
    decide,
    find_discrepancy,
    split_fit_holdout,
)
from fuelhm_bench.calibration.synthetic import TEST_RANGES, draw_magnitude, hidden_effect_flights
from fuelhm_bench.cli import main
from fuelhm_bench.errors import DataFormatError, UnknownNameError
from fuelhm_bench.io import FlightArrays, split_flights, write_flights
from fuelhm_bench.physics.model import load_model
from fuelhm_bench.taxonomy import EFFECT_IDS
from sizes import DISCREPANCY_FLIGHTS, DISCREPANCY_MINUTES, DISCREPANCY_UNITS, discrepancy_config

#: Small instances (tests/sizes.py): 2 units x 2 flights of 4 min, fit frames capped.
SMALL = discrepancy_config()
#: Seed of each hidden-effect data set (the magnitude is drawn from it in TEST_RANGES).
SEEDS = {"spool_overlap": 21, "spool_flow_force": 22, "rod_friction": 23, "lvdt_lag": 24, "load_stiffness": 25,
         "none": 26, "current_driver_lag": 27, "torque_motor_hysteresis": 28,
         "viscosity_temperature": 29}


def _data(effect, **kw):
    frame, case = hidden_effect_flights(effect, n_units=DISCREPANCY_UNITS, n_flights=DISCREPANCY_FLIGHTS,
                                        minutes=DISCREPANCY_MINUTES, seed=SEEDS[effect or "none"],
                                        **kw)
    flights, rejected = split_flights(frame)
    assert not rejected
    return frame, flights, case


# One case per effect, every candidate ranked (20-35 s each on a quiet 2-core machine): run with ``-m slow``.
# The default run keeps the workflow end to end through the CLI (spool_overlap, three candidates), on
# another sample rate with every candidate (lvdt_lag), and without a hidden effect (none).
@pytest.mark.slow
@pytest.mark.parametrize("effect", EFFECT_IDS)
def test_names_the_hidden_effect_and_shrinks_the_heldout_gap(effect):
    _, flights, case = _data(effect)
    result = find_discrepancy(flights, config=SMALL)
    assert result.effect == effect, [(c.effect, round(c.delta_bic), round(c.gap_reduction, 2)) for c in result.ranking]
    assert result.gap_after <= 0.5 * result.gap_before
    assert result.gap_after < result.gap_recalibrated
    main_param = TEST_RANGES[effect][0]
    truth, fitted = case.parameters[main_param], result.parameters[main_param]
    assert abs(fitted - truth) <= 0.35 * abs(truth), (fitted, truth)
    # The augmented model carries the effect with the fitted values; the ranking is by BIC.
    assert result.model.effect(effect) is not None
    bics = [c.bic for c in result.ranking]
    assert bics == sorted(bics)
    assert result.ranking[0].effect == effect and result.ranking[0].eligible
    assert set(c.effect for c in result.ranking) == set(EFFECT_IDS) | {"none"}


@pytest.mark.slow  # 14 s; the default run covers the `none` verdict on healthy data of the second simulator
# (test_discrepancy_verdicts.py::test_verdict_none_on_healthy_altsim_data, 4 s)
def test_answers_none_without_a_hidden_effect():
    _, flights, _ = _data(None)
    result = find_discrepancy(flights, config=SMALL)
    assert result.effect == "none"
    assert result.parameters == {}
    assert result.model.effects == ()
    assert result.gap_after == result.gap_recalibrated < 0.5 * result.gap_before
    assert not any(c.eligible for c in result.ranking)
    assert result.region.startswith("no significant disagreement")


def test_other_sample_rate_noise_and_flight_length():
    frame, case = hidden_effect_flights("lvdt_lag", parameters={"time_constant_s": 0.04}, n_units=1, n_flights=3,
                                        minutes=6.0, frame_s=0.02, noise_std_m=8e-6, seed=31)
    flights, _ = split_flights(frame)
    assert np.median(np.diff(flights[0].time_s)) == pytest.approx(0.02)
    result = find_discrepancy(flights, config=SMALL)
    assert result.frame_s == pytest.approx(0.02)
    assert result.model.controller.frame_s == pytest.approx(0.02)
    assert result.effect == "lvdt_lag"
    assert result.parameters["time_constant_s"] == pytest.approx(0.04, rel=0.3)
    assert result.gap_after <= 0.5 * result.gap_before


def test_split_is_seeded_stratified_and_complete():
    flights = [FlightArrays(i, f"U{i % 3}", np.arange(3.0), np.arange(3.0), np.arange(3.0)) for i in range(10)]
    fit, held = split_fit_holdout(flights, 0.3, seed=4)
    assert len(held) == 3 and len(fit) == 7
    assert {f.flight_id for f in fit} | {f.flight_id for f in held} == set(range(10))
    assert {f.unit_id for f in fit} == {"U0", "U1", "U2"}  # every unit keeps fit flights
    again = split_fit_holdout(flights, 0.3, seed=4)
    assert [f.flight_id for f in again[1]] == [f.flight_id for f in held]
    two = split_fit_holdout([flights[0], flights[3]], 0.3, seed=0)  # one unit, two flights
    assert len(two[0]) == 1 and len(two[1]) == 1
    with pytest.raises(DataFormatError, match="Too few flights to hold out"):
        split_fit_holdout(flights[:1])  # one flight of 3 s: too short to cut in time
    with pytest.raises(DataFormatError, match="Too few flights to hold out"):
        split_fit_holdout(flights[:2])  # two units of one short flight each


def test_split_cuts_single_flight_units_into_blocks():
    # Every unit replays its held-out data through its own recalibrated model: a unit with one
    # flight holds out blocks spread over that flight, never the whole flight (it would be replayed
    # through the fleet's mean model, and its manufacturing dispersion would read as a discrepancy).
    t = np.arange(0.0, 600.0, 0.01)  # 20 blocks of 30 s
    one = [FlightArrays(i, f"U{i}", t, np.sin(t + i), np.cos(t)) for i in range(3)]
    many = [FlightArrays(10 + i, "M", t, np.sin(t), np.cos(t)) for i in range(4)]
    fit, held = split_fit_holdout(one + many, 0.3, seed=1)
    assert {f.unit_id for f in held} == {"U0", "U1", "U2", "M"} == {f.unit_id for f in fit}
    parts = {f.flight_id: f for f in held if f.unit_id != "M"}
    assert set(parts) == {"0/held-out", "1/held-out", "2/held-out"}
    part, rest = parts["0/held-out"], next(f for f in fit if f.flight_id == 0)
    assert part.n_samples + rest.n_samples == t.size
    blocks = np.unique(np.floor(part.time_s / 30.0))
    assert blocks.size == 6 and blocks.min() >= 1 and np.diff(blocks).min() >= 2  # spread, not a tail
    assert np.array_equal(np.sort(np.concatenate([part.time_s, rest.time_s])), t)
    assert sum(f.unit_id == "M" for f in held) == 1  # round(0.3 * 4) of the multi-flight unit
    fit1, held1 = split_fit_holdout(one[:1], 0.3)  # a single long flight is enough
    assert [f.flight_id for f in fit1] == [0] and [f.flight_id for f in held1] == ["0/held-out"]
    short = FlightArrays(5, "S", np.arange(0.0, 50.0, 0.01), np.zeros(5000), np.zeros(5000))
    fit2, held2 = split_fit_holdout(many[:2] + [short], 0.3)  # two blocks only: kept for fitting
    assert short in fit2 and all(f.unit_id == "M" for f in held2)


def _outcome(effect, delta_bic, reduction, bic=None):
    return CandidateOutcome(effect, {}, -delta_bic if bic is None else bic, delta_bic, 1.0, 1.0, reduction, False,
                            1, 0.0, {})


def test_decision_rule():
    none = _outcome("none", 0.0, 0.0)
    rule = {"bic_threshold": 10.0, "min_gap_reduction": 0.3}
    assert decide([none, _outcome("lvdt_lag", 500.0, 0.8)], **rule) == "lvdt_lag"
    # Large BIC gain without a held-out gain: none.
    assert decide([none, _outcome("lvdt_lag", 500.0, 0.1)], **rule) == "none"
    # Held-out gain without enough BIC gain: none.
    assert decide([none, _outcome("lvdt_lag", 5.0, 0.9)], **rule) == "none"
    # Two eligible candidates: the lower BIC wins, even with a smaller held-out gain.
    assert decide([none, _outcome("rod_friction", 300.0, 0.9), _outcome("spool_overlap", 900.0, 0.5)],
                  **rule) == "spool_overlap"
    # An overlap fitted at no lap (explaining through its clearance alone) cannot be named.
    off = dataclasses.replace(_outcome("spool_overlap", 900.0, 0.5), effect_off=True)
    assert decide([none, off], **rule) == "none"
    assert decide([none, off, _outcome("rod_friction", 300.0, 0.9)], **rule) == "rod_friction"


def test_an_effect_at_the_low_end_of_its_log_range_is_off():
    from fuelhm_bench.calibration.candidates import candidates

    lib = candidates()
    lap = lib["spool_overlap"]
    assert lap.is_off({"overlap_m": 1.08e-7, "servovalve.radial_clearance_m": 1.6e-5})  # healthy altsim fits
    assert not lap.is_off({"overlap_m": 3.9e-6, "servovalve.radial_clearance_m": 1e-5})  # a 4 um lap is on
    assert lib["rod_friction"].is_off({"coulomb_n": 1.0, "static_ratio": 2.0})
    assert not lib["rod_friction"].is_off({"coulomb_n": 40.0, "static_ratio": 1.0})
    # a stiffness has no "off" end (it is signed): never off
    assert not lib["load_stiffness"].is_off({"stiffness_n_m": 0.0, "reference_m": 0.03})


def test_too_few_flights_and_no_transient_are_refused():
    _, flights, _ = _data(None)
    one = flights[0]
    short = one._take(np.flatnonzero(one.time_s - one.time_s[0] < 60.0))  # too short to cut into 3 blocks of 30 s
    with pytest.raises(DataFormatError, match="Too few flights to hold out: got 1"):
        find_discrepancy([short], config=SMALL)
    t = np.arange(18000) * 0.01
    rng = np.random.default_rng(1)
    still = [FlightArrays(k, "U", t, 0.3 + 0.003 * rng.standard_normal(t.size),
                          30.0 + 0.017 * np.round(rng.standard_normal(t.size)),
                          extras={"n2_pct": np.full(t.size, 80.0)}) for k in range(3)]
    with pytest.raises(DataFormatError, match="Not enough excitation.*moving samples.*test sweep"):
        find_discrepancy(still, config=SMALL)


def test_unknown_candidate_is_refused():
    _, flights, _ = _data(None)
    with pytest.raises(UnknownNameError, match="Unknown candidate effect 'stiction'"):
        find_discrepancy(flights, config=DiscrepancyConfig(candidates=("stiction",)))


def test_a_candidate_sets_its_effect_fields_and_the_model_parameters_its_law_uses():
    from fuelhm_bench.calibration.candidates import candidates, parameter_key
    from fuelhm_bench.physics.model import LoopModel

    lib = candidates()
    lap = lib["spool_overlap"]
    keys = [parameter_key(p.path) for p in lap.parameters]
    assert keys == ["overlap_m", "servovalve.radial_clearance_m"]
    m = lap.apply(LoopModel(), {"overlap_m": 2e-5, "servovalve.radial_clearance_m": 1.1e-5})
    assert m.effect("spool_overlap").overlap_m == 2e-5 and m.servovalve.radial_clearance_m == 1.1e-5
    # every other candidate fits its effect's own fields only, each within the effect's range
    for cand in lib.values():
        for p in cand.parameters:
            assert p.path.startswith(f"effect.{cand.effect}.") or p is lap.parameters[1]
        cand.apply(LoopModel(), cand.start_values(cand.grid[0]))


def test_draw_magnitude_is_seeded_and_in_range():
    for effect, (name, lo, hi) in TEST_RANGES.items():
        a = draw_magnitude(effect, np.random.default_rng(3))[name]
        assert a == draw_magnitude(effect, np.random.default_rng(3))[name]
        assert lo <= abs(a) <= hi


@pytest.fixture(scope="module")
def overlap_file(tmp_path_factory):
    frame, _, case = _data("spool_overlap")
    path = write_flights(frame, tmp_path_factory.mktemp("disc") / "measured.parquet")
    return path, case


def test_cli_json_prints_one_object_and_out_writes_the_report(overlap_file, tmp_path, capsys):
    path, case = overlap_file
    out = tmp_path / "report"
    code = main(["discrepancy", str(path), "--json", "--out", str(out), "--seed", "2",
                 "--candidates", "spool_overlap,lvdt_lag,torque_motor_hysteresis"])
    captured = capsys.readouterr()
    assert code == 0
    payload = json.loads(captured.out)  # exactly one JSON object, nothing else on stdout
    assert isinstance(payload, dict)
    for key in ("effect", "parameters", "region", "gap_metric", "gap_before", "gap_after", "ranking"):
        assert key in payload
    assert payload["effect"] == "spool_overlap"
    assert payload["parameters"]["overlap_m"]["unit"] == "m"
    assert payload["gap_after"] <= 0.5 * payload["gap_before"]
    assert {r["effect"] for r in payload["ranking"]} == {"spool_overlap", "lvdt_lag", "torque_motor_hysteresis", "none"}
    assert all({"effect", "bic", "gap_after"} <= set(r) for r in payload["ranking"])
    assert "split:" in captured.err  # logs go to stderr
    # 2 units x 2 flights x 4 min: short flights and one held-out flight weaken the evidence; the
    # caveats are in the JSON, the log and the report, and leave the verdict alone.
    assert [c["code"] for c in payload["caveats"]] == ["short_flights", "few_heldout"]
    assert "median 4.0 min" in payload["caveats"][0]["message"]
    assert "caveat (short_flights)" in captured.err and payload["verdict"] == "effect"
    for name in ("report.md", "augmented_model.yaml", "result.json", "curves.png", "residual_map.png", "regions.png"):
        assert (out / name).stat().st_size > 0
    model = load_model(out / "augmented_model.yaml")
    assert model.effect("spool_overlap").overlap_m == pytest.approx(payload["parameters"]["overlap_m"]["value"])
    report = (out / "report.md").read_text()
    assert "Missing effect: `spool_overlap`" in report and "![curves](curves.png)" in report
    assert "**Caveats" in report and "- `few_heldout`: 1 held-out flight(s)" in report
    # The augmented model simulates.
    sim = tmp_path / "sim.parquet"
    assert main(["simulate", "--model", str(out / "augmented_model.yaml"), "--units", "1", "--flights", "1",
                 "--minutes", "2", "--out", str(sim)]) == 0
    assert len(pd.read_parquet(sim)) == 12000
    # The report directory is not overwritten without --force.
    assert main(["discrepancy", str(path), "--out", str(out), "--candidates", "lvdt_lag"]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err


def test_cli_bad_inputs_give_clear_messages(overlap_file, tmp_path, capsys):
    path, _ = overlap_file
    broken = tmp_path / "model.yaml"
    broken.write_text("cylinder:\n  bore_m: -1\n")
    assert main(["discrepancy", str(path), "--model", str(broken), "--json"]) == 2
    captured = capsys.readouterr()
    error = json.loads(captured.out)  # --json: exactly one object, also when the command fails
    assert error["verdict"] is None and error["exit_status"] == 2 and "bore_m" in error["error"]
    assert "model.yaml" in captured.err and "bore_m" in captured.err
    with pytest.raises(SystemExit) as exit_info:  # a command-line mistake (argparse) too
        main(["discrepancy", str(path), "--jobs", "0", "--json"])
    captured = capsys.readouterr()
    assert exit_info.value.code == 2 and "--jobs" in captured.err
    assert json.loads(captured.out) == {"verdict": None, "exit_status": 2,
                                        "error": "fuelhm-bench discrepancy: error: argument --jobs: must be an "
                                                 "integer >= 1, got 0"}
    assert main(["discrepancy", str(tmp_path / "nothing.parquet")]) == 2
    assert "nothing.parquet" in capsys.readouterr().err
    frame = pd.read_parquet(path).drop(columns=["current_mA"])
    bad = tmp_path / "bad.csv"
    frame.to_csv(bad, index=False)
    assert main(["discrepancy", str(bad)]) == 2
    assert "missing the required column(s) ['current_mA']" in capsys.readouterr().err
    one = tmp_path / "one.parquet"
    full = pd.read_parquet(path)
    first = full[full["flight_id"] == full["flight_id"].iloc[0]]
    write_flights(first[first["time_s"] - first["time_s"].iloc[0] < 60.0], one)  # one flight, too short to cut
    assert main(["discrepancy", str(one)]) == 2
    assert "Too few flights to hold out" in capsys.readouterr().err
