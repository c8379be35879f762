"""Plausibility rules F6-F9 of the flight reader, and the commands that must not draw nonsense.

Each unit mistake of issue 9 section 3 (current in A, position in m, time in
ms, absurd values) is refused with a message naming the file, the column, the
observed range and the likely mistake.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.cli import main
from fuelhm_bench.errors import DataFormatError
from fuelhm_bench.io import BENCH_PHASE, read_flights, write_flights


def flight_table(n_flights: int = 2, n: int = 3000, dt: float = 0.01) -> pd.DataFrame:
    """Plausible flights in file units: a current swinging +-6 mA moving the rod within 3-57 mm."""
    rng = np.random.default_rng(0)
    frames = []
    for k in range(n_flights):
        t = np.arange(n) * dt
        current = 6.0 * np.sin(2 * np.pi * t / 7.0) + 0.05 * rng.standard_normal(n)
        velocity = 8.0 * current  # mm/s
        position = np.clip(30.0 + np.cumsum(velocity) * dt, 3.0, 57.0)
        frames.append(pd.DataFrame({"flight_id": k, "time_s": t, "current_mA": current,
                                    "position_mm": np.round(position / 0.015) * 0.015}))
    return pd.concat(frames, ignore_index=True)


def read_mutated(tmp_path, **changes) -> str:
    table = flight_table()
    for column, change in changes.items():
        table[column] = change(table[column].to_numpy())
    path = tmp_path / "bad.parquet"
    table.to_parquet(path)
    with pytest.raises(DataFormatError) as info:
        read_flights(path)
    message = str(info.value)
    assert str(path) in message
    return message


def test_plausible_table_reads(tmp_path):
    path = tmp_path / "ok.csv"
    flight_table().to_csv(path, index=False)
    assert len(read_flights(path)) == 6000


def test_f7_current_in_amperes(tmp_path):
    message = read_mutated(tmp_path, current_mA=lambda i: i / 1000.0)
    assert re.search(r"Column 'current_mA' .* ranges over only \[-0\.006\d*, 0\.006\d*\] mA", message), message
    assert "It looks like amperes instead of milliamperes (multiply by 1000)." in message


def test_f7_position_in_metres(tmp_path):
    message = read_mutated(tmp_path, position_mm=lambda x: x / 1000.0)
    assert re.search(r"Column 'position_mm' .* ranges over only \[0\.0\d+, 0\.057\] mm", message), message
    assert "metres instead of millimetres" in message


def test_f6_current_in_microamperes(tmp_path):
    message = read_mutated(tmp_path, current_mA=lambda i: i * 1000.0)
    assert "outside its plausible range [-100, 100] mA" in message
    assert "microamperes instead of milliamperes (divide by 1000)" in message


def test_f6_position_in_micrometres(tmp_path):
    message = read_mutated(tmp_path, position_mm=lambda x: x * 1000.0)
    assert re.search(r"Column 'position_mm' .* ranges over \[[\d.e+]+, 5\.7e\+04\] mm", message), message
    assert "micrometres instead of millimetres" in message


def test_f6_absurd_value(tmp_path):
    def spike(x):
        x = x.copy()
        x[17] = 1e30
        return x

    message = read_mutated(tmp_path, current_mA=spike)
    assert "1 value(s) are out of range, the most extreme 1e+30 mA: not a measurement" in message


def test_f7_demand_in_metres_and_n2_as_a_fraction(tmp_path):
    table = flight_table()
    table["demand_mm"] = table["position_mm"] / 1000.0
    path = tmp_path / "demand.parquet"
    table.to_parquet(path)
    with pytest.raises(DataFormatError, match=r"Column 'demand_mm' .* metres instead of millimetres") as info:
        read_flights(path)
    assert str(path) in str(info.value)
    table = flight_table()
    table["n2_pct"] = np.linspace(0.55, 0.97, len(table))  # N2 as a fraction of the rated speed
    table.to_parquet(path)
    with pytest.raises(DataFormatError, match=r"Column 'n2_pct' .* ranges over only \[0\.55, 0\.97\] % .* fraction "
                                              r"of the rated speed instead of percent \(multiply by 100\)"):
        read_flights(path)
    table["n2_pct"] = 0.0  # an engine-off recording is allowed
    table.to_parquet(path)
    assert (read_flights(path)["n2_pct"] == 0.0).all()


def test_f8_ignores_flights_out_of_time_order(tmp_path):
    """Shuffled rows are not mistaken for milliseconds: P4 rejects each flight, saying why."""
    from fuelhm_bench.io import split_flights

    table = flight_table().sample(frac=1.0, random_state=3).reset_index(drop=True)
    path = tmp_path / "shuffled.parquet"
    table.to_parquet(path)
    flights, rejected = split_flights(read_flights(path), source=str(path))
    assert flights == [] and len(rejected) == 2
    assert all("the samples of a flight must be in increasing time order" in r.reason for r in rejected)
    ordered = flight_table()  # one flight in order, one shuffled: F8 judges the ordered one
    ordered.loc[ordered["flight_id"] == 1] = ordered.loc[ordered["flight_id"] == 1].sample(frac=1.0, random_state=4).to_numpy()
    ordered.to_parquet(path)
    assert [f.flight_id for f in split_flights(read_flights(path))[0]] == [0]
    ordered["time_s"] *= 1000.0  # and still catches milliseconds in it
    ordered.to_parquet(path)
    with pytest.raises(DataFormatError, match="milliseconds instead of seconds"):
        read_flights(path)


@pytest.mark.parametrize("flip", ["current", "position"])
def test_f9_reversed_sign_convention(tmp_path, flip):
    table = flight_table()
    if flip == "current":
        table["current_mA"] = -table["current_mA"]
    else:
        table["position_mm"] = 60.0 - table["position_mm"]
    path = tmp_path / "flipped.parquet"
    table.to_parquet(path)
    with pytest.raises(DataFormatError) as info:
        read_flights(path)
    message = str(info.value)
    assert str(path) in message and "falls when current_mA rises" in message
    assert re.search(r"correlation is -0\.\d\d \(median over 2 flight\(s\), negative in 2\)", message), message
    assert "negate current_mA" in message and "stroke - position" in message


def test_f9_needs_a_majority_and_enough_steps(tmp_path):
    table = flight_table(3)
    table.loc[table["flight_id"] == 2, "current_mA"] *= -1.0  # one odd flight of three: read
    path = tmp_path / "one.parquet"
    table.to_parquet(path)
    assert len(read_flights(path)) == len(table)
    short = flight_table(2, n=60)  # under 100 steps a flight does not count
    short["current_mA"] *= -1.0
    short.to_parquet(path)
    assert len(read_flights(path)) == 120


def test_f6_and_f8_time_in_milliseconds(tmp_path):
    message = read_mutated(tmp_path, time_s=lambda t: t * 1000.0)
    assert "Column 'time_s'" in message and "median sampling interval of 10 s" in message
    assert "milliseconds instead of seconds (divide by 1000)" in message


def test_f6_fuel_temperature_in_kelvin(tmp_path):
    table = flight_table()
    table["fuel_temp_degC"] = 288.0 + np.linspace(0, 50, len(table))
    path = tmp_path / "k.parquet"
    table.to_parquet(path)
    with pytest.raises(DataFormatError, match="kelvin instead of degrees Celsius"):
        read_flights(path)


def test_f6_n2_in_rpm(tmp_path):
    table = flight_table()
    table["n2_pct"] = np.linspace(8500.0, 15200.0, len(table))
    path = tmp_path / "rpm.parquet"
    table.to_parquet(path)
    with pytest.raises(DataFormatError, match=r"Column 'n2_pct' .* It looks like revolutions per minute instead of "
                                              r"percent of the reference speed"):
        read_flights(path)


def test_bench_samples_are_exempt_from_the_position_range(tmp_path):
    table = flight_table(1)
    table["position_mm"] = np.linspace(-1500.0, 1600.0, len(table))
    table["phase"] = BENCH_PHASE
    path = tmp_path / "bench.parquet"
    write_flights(table, path)
    assert read_flights(path)["position_mm"].max() == 1600.0
    table["phase"] = "cruise"
    write_flights(table, path, overwrite=True)
    with pytest.raises(DataFormatError, match=f"phase '{BENCH_PHASE}'"):
        read_flights(path)


@pytest.mark.parametrize("command", ["discrepancy", "calibrate"])
def test_commands_say_when_every_flight_was_rejected(tmp_path, capsys, command):
    table = flight_table()
    table["position_mm"] = 30.0  # both flights: a stuck sensor (rule P9)
    src = tmp_path / "stuck.csv"
    table.to_csv(src, index=False)
    out = tmp_path / ("report" if command == "discrepancy" else "model.yaml")
    assert main([command, str(src), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{src}: every flight of the file was rejected (2 flight(s))" in err
    assert "a stuck or disconnected position sensor" in err and not out.exists()


@pytest.mark.parametrize("command", ["indicators", "plot-curve"])
def test_commands_refuse_current_in_amperes_and_write_nothing(tmp_path, capsys, command):
    table = flight_table()
    table["current_mA"] /= 1000.0
    src = tmp_path / "amps.csv"
    table.to_csv(src, index=False)
    out = tmp_path / ("out.csv" if command == "indicators" else "out.png")
    assert main([command, str(src), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "current_mA" in err and "amperes" in err and str(src) in err
    assert not out.exists() and list(tmp_path.iterdir()) == [src]


def test_indicators_refuses_a_table_without_a_valid_indicator(tmp_path, capsys):
    table = flight_table(1, n=400)
    table["position_mm"] = 60.0 + 0.015 * (np.arange(len(table)) % 2)  # rod on the end stop: every sample masked
    src = tmp_path / "stuck.csv"
    table.to_csv(src, index=False)
    out = tmp_path / "ind.csv"
    assert main(["indicators", str(src), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "no flight has a single valid indicator, so no table is written" in err and "0 idle samples" in err
    assert not out.exists()


def test_plot_curve_draws_a_sweep_overlay(tmp_path, capsys):
    """The README's `--overlay sweep.parquet` example: the bench sweep keeps its samples."""
    sweep = tmp_path / "sweep.parquet"
    assert main(["sweep", "--ramp-seconds", "10", "--out", str(sweep)]) == 0
    png = tmp_path / "sweep.png"
    assert main(["plot-curve", str(sweep), "--out", str(png)]) == 0
    out = capsys.readouterr().out
    n_points = int(re.search(r"(\d+) raw points", out).group(1))
    assert n_points > 0.95 * 2000  # 2 x 10 s at 100 Hz; the end-stop mask used to keep under 1 %
    assert png.stat().st_size > 0
