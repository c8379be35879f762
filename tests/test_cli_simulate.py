"""CLI: simulate, sweep, plot-curve (files in the format of docs/data-format.md, labels, errors, determinism)."""

from __future__ import annotations

import os

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.cli import main
from fuelhm_bench.io import read_flights, read_labels


def _sim(tmp_path, name="f.parquet", *extra):
    out = tmp_path / name
    code = main(["simulate", "--units", "2", "--flights", "2", "--minutes", "2", "--seed", "3", *extra,
                 "--out", str(out)])
    assert code == 0
    return out


def test_simulate_writes_data_format_and_labels(tmp_path):
    out = _sim(tmp_path, "f.parquet", "--degrade", "internal_leakage:0.6", "--onset", "1-1")
    flights = read_flights(out)
    assert {"flight_id", "time_s", "current_mA", "position_mm", "unit_id", "n2_pct", "phase"} <= set(flights)
    assert flights["flight_id"].nunique() == 4
    labels = read_labels(tmp_path / "f.labels.parquet")
    assert list(labels["flight_index"]) == [0, 1, 0, 1]
    # Step growth from onset flight 1: healthy on flight 0, 0.6 from flight 1.
    assert list(labels["intensity_internal_leakage"]) == [0.0, 0.6, 0.0, 0.6]
    assert (labels["onset_internal_leakage"] == 1).all()
    # Ground truth never appears in the measurements.
    assert not any(c.startswith("intensity") for c in flights.columns)


def test_simulate_is_deterministic(tmp_path):
    a = _sim(tmp_path, "a.parquet")
    b = _sim(tmp_path, "b.parquet")
    pd.testing.assert_frame_equal(pd.read_parquet(a), pd.read_parquet(b))
    c = tmp_path / "c.csv"
    assert main(["simulate", "--units", "2", "--flights", "2", "--minutes", "2", "--seed", "4", "--out", str(c)]) == 0
    assert not np.array_equal(pd.read_parquet(a)["position_mm"], pd.read_csv(c)["position_mm"])


def test_simulate_batching_does_not_change_output(tmp_path):
    a = _sim(tmp_path, "a.parquet", "--batch-size", "1")
    b = _sim(tmp_path, "b.parquet", "--batch-size", "3")
    pd.testing.assert_frame_equal(pd.read_parquet(a), pd.read_parquet(b))


def test_simulate_effect_and_frame_rate(tmp_path):
    out = _sim(tmp_path, "e.parquet", "--effect", "lvdt_lag:time_constant_s=0.03", "--frame-rate", "50")
    f = read_flights(out)
    assert np.allclose(np.diff(f[f.flight_id == 0]["time_s"]), 0.02)
    assert read_labels(tmp_path / "e.labels.parquet")["hidden_effects"].iloc[0] == "lvdt_lag"


@pytest.mark.parametrize("args, message", [
    (["--degrade", "backlsh:0.5"], "Did you mean 'backlash'"),
    (["--degrade", "backlash:1.5"], r"in \[0, 1\]\. Got 1.5"),
    (["--degrade", "backlash"], "expected MODE:INTENSITY"),
    (["--effect", "rod_fricton"], "Did you mean 'rod_friction'"),
    (["--effect", "rod_friction:coulomb_n=-1"], "coulomb_n"),
    (["--onset", "5-2"], "--onset must be MIN-MAX"),
    # each was accepted before: labels with two schedules of one mode, an effect silently replaced, an onset unused
    (["--degrade", "backlash:0.2", "--degrade", "backlash:0.9"], "--degrade backlash is given twice"),
    (["--effect", "rod_friction:coulomb_n=100", "--effect", "rod_friction"], "--effect rod_friction is given twice"),
    (["--onset", "0-0"], "--onset 0-0 applies to the degradations of --degrade, and none is given"),
])
def test_simulate_bad_input_is_one_clean_line(tmp_path, capsys, args, message):
    code = main(["simulate", "--units", "1", "--flights", "1", "--minutes", "2", *args, "--out", str(tmp_path / "x.parquet")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error: ") and err.count("\n") == 1
    assert pytest.importorskip("re").search(message, err)


def test_simulate_zero_duration_and_counts_rejected_by_argparse(tmp_path, capsys):
    for args in (["--minutes", "0"], ["--units", "0"], ["--flights", "-1"]):
        with pytest.raises(SystemExit) as exc:
            main(["simulate", *args, "--out", str(tmp_path / "x.parquet")])
        assert exc.value.code == 2
    assert "must be" in capsys.readouterr().err


def test_simulate_refuses_to_overwrite(tmp_path, capsys):
    out = _sim(tmp_path)
    before = out.read_bytes()
    assert main(["simulate", "--units", "1", "--flights", "1", "--minutes", "2", "--out", str(out)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert main(["simulate", "--units", "1", "--flights", "1", "--minutes", "2", "--out", str(out), "--force"]) == 0


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write anywhere")
def test_simulate_unwritable_directory(tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    assert main(["simulate", "--units", "1", "--flights", "1", "--minutes", "2", "--out", str(locked / "f.parquet")]) == 2
    assert "Cannot write" in capsys.readouterr().err


def test_simulate_output_path_is_a_directory(tmp_path, capsys):
    assert main(["simulate", "--units", "1", "--flights", "1", "--minutes", "2", "--out", str(tmp_path)]) == 2
    assert "is a directory" in capsys.readouterr().err


def test_sweep_and_plot_curve(tmp_path):
    sw = tmp_path / "sweep.csv"
    assert main(["sweep", "--ramp-seconds", "20", "--degrade", "null_bias_drift:0.5", "--out", str(sw)]) == 0
    table = pd.read_csv(sw)
    assert table["current_mA"].min() == pytest.approx(-12.0) and table["current_mA"].max() == pytest.approx(12.0)
    assert (np.sign(table["velocity_true_mm_s"].iloc[-10:]) < 0).all()
    flights = _sim(tmp_path, "f.parquet", "--minutes", "3")
    png = tmp_path / "curve.png"
    assert main(["plot-curve", str(flights), "--annotate", "--out", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    over = tmp_path / "over.png"
    assert main(["plot-curve", str(flights), "--flight", "0", "--flight", "1", "--overlay", f"{sw}=sweep",
                 "--out", str(over)]) == 0
    assert over.stat().st_size > 10_000


def test_plot_curve_unknown_flight(tmp_path, capsys):
    flights = _sim(tmp_path)
    assert main(["plot-curve", str(flights), "--flight", "99", "--out", str(tmp_path / "c.png")]) == 2
    assert "no usable flight with id '99'" in capsys.readouterr().err


def test_every_command_has_help(capsys):
    from fuelhm_bench.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name in sub.choices:
        with pytest.raises(SystemExit) as exc:
            main([name, "--help"])
        assert exc.value.code == 0
    assert "usage" in capsys.readouterr().out


def test_simulate_output_under_a_file_is_unwritable(tmp_path, capsys):
    blocker = tmp_path / "blocker"
    blocker.write_text("not a directory")
    assert main(["simulate", "--units", "1", "--flights", "1", "--minutes", "2",
                 "--out", str(blocker / "f.parquet")]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and f"'{blocker}' is a file, not a directory" in err
