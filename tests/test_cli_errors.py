"""Command-line misuse: every bad option gets one line naming the option, and Ctrl-C exits 130 cleanly."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fuelhm_bench.cli import main
from fuelhm_bench.cli._common import option_message
from fuelhm_bench.errors import range_error


def run(capsys, *argv) -> tuple[int, str]:
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse usage errors
        code = exc.code
    err = capsys.readouterr().err
    return code, err


@pytest.mark.parametrize("argv,expected", [
    (["simulate", "--minutes", "0.5"], "argument --minutes: must be a number in [2, 1440] min. Got 0.5 instead."),
    (["simulate", "--minutes", "1e9"], "argument --minutes: must be a number in [2, 1440] min. Got 1e9 instead."),
    (["simulate", "--units", "1e26"], "argument --units: must be an integer in [1, 10000]. Got '1e26' instead."),
    (["simulate", "--flights", "1000000000000"], "argument --flights: must be an integer in [1, 10000]."),
    (["simulate", "--noise-um", "nan"], "argument --noise-um: must be a number in [0, 10000] um. Got nan instead."),
    (["simulate", "--adc-bits", "99"], "argument --adc-bits: must be an integer in [0, 24]. Got 99 instead."),
    (["simulate", "--frame-rate", "1e9"], "argument --frame-rate: must be a number in [1, 10000] Hz."),
    (["simulate", "--dispersion", "-1"], "argument --dispersion: must be a number in [0, 3]. Got -1 instead."),
    (["simulate", "--dispersion", "5"], "argument --dispersion: must be a number in [0, 3]. Got 5 instead."),
    (["simulate", "--flights", "5", "--onset", "8-12", "--degrade", "internal_leakage:0.5"],
     "error: --onset must be MIN-MAX with MAX <= --flights - 1 = 4 (onsets are 0-based flight indices"),
    (["simulate", "--onset", "x-y", "--degrade", "internal_leakage:0.5"],
     "error: --onset must be MIN-MAX with integers >= 0. Got 'x-y' instead."),
    (["simulate", "--effect", "rod_friction:coulomb_n=abc"],
     "error: --effect 'rod_friction:coulomb_n=abc': the value of 'coulomb_n' must be a number. Got 'abc' instead."),
    (["simulate", "--effect", "rod_frictio"], "error: --effect 'rod_frictio': Unknown effect id 'rod_frictio'."),
    (["simulate", "--degrade", "internal_leakage"], "error: --degrade 'internal_leakage': expected MODE:INTENSITY"),
    (["simulate", "--degrade", "internal_leakage:abc"],
     "error: --degrade 'internal_leakage:abc': the intensity must be a number in [0, 1]. Got 'abc' instead."),
    (["simulate", "--degrade", "internal_leakage:2"], "the intensity must be a number in [0, 1]. Got 2 instead."),
    (["simulate", "--degrade", "internal_leakge:0.5"], "Did you mean 'internal_leakage'?"),
    (["simulate", "--units", "10000", "--flights", "10000"],
     "error: --units 10000 x --flights 10000 x --minutes 60 is 1e+08 flight-hours"),
    (["sweep", "--n2-pct", "500"], "error: --n2-pct must be in [30, 110] %. Got 500 instead."),
    (["sweep", "--min-ma", "5", "--max-ma", "1"], "error: --max-ma must be > --min-ma (5 mA). Got 1 instead."),
    (["sweep", "--cycles", "100", "--ramp-seconds", "3600"], "error: --cycles 100 x 2 x --ramp-seconds 3600"),
    (["sweep", "--noise-um", "5", "--seed", "3"], "error: --noise-um, --seed: a sweep records the true rod position"),
    (["itl", "--intensities", "0.5,abc"], "error: --intensities must be comma-separated numbers in (0, 1]."),
    (["itl", "--intensities", "0.5,0.5"], "error: --intensities must hold at least two distinct values in (0, 1]"),
    (["itl", "--intensities", "1"], "error: --intensities must hold at least two distinct values in (0, 1]"),
    (["discrepancy", "f.parquet", "--candidates", "rod_frction"], "error: --candidates: unknown effect "
                                                                  "'rod_frction'."),
    (["plot-curve", "missing.parquet"], "error: The flight file 'missing.parquet' does not exist."),
])
def test_bad_option_names_the_option(tmp_path, capsys, monkeypatch, argv, expected):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("FUELHM_RUN_BUDGET_FLIGHT_HOURS", raising=False)
    if argv[0] in ("simulate", "sweep", "plot-curve"):
        argv = argv + ["--out", str(tmp_path / ("o.png" if argv[0] == "plot-curve" else "o.parquet"))]
    if argv[0] == "itl":
        argv = argv + ["--out", str(tmp_path / "itl")]
    code, err = run(capsys, *argv)
    assert code == 2
    assert expected in err, err
    assert "Traceback" not in err
    assert sum("error:" in line for line in err.splitlines()) == 1  # one error line (argparse adds its usage)
    assert not (tmp_path / "o.parquet").exists() and not (tmp_path / "o.png").exists()


def test_option_message_maps_internal_fields_to_options():
    import argparse

    args = argparse.Namespace(minutes=0.5, frame_rate=5e4, noise_um=-1.0)
    assert option_message(str(range_error("MissionProfile.duration_s", ">= 120", 30.0)), args) == \
        "--minutes must be >= 2 min. Got 0.5 instead."
    assert option_message(str(range_error("ControllerParams.frame_s", "in [0.0001, 1]", 2e-5)), args) == \
        "--frame-rate must be in [1, 10000] Hz. Got 50000 instead."
    assert option_message(str(range_error("LvdtParams.noise_std_m", ">= 0", -1e-6)), args) == \
        "--noise-um must be >= 0 um. Got -1 instead."
    other = str(range_error("Dispersion.scale", "in [0, 3]", -1.0))
    assert option_message(other, args) == other  # this command has no --dispersion: unchanged


def test_dispersion_is_held_to_what_the_model_can_manufacture(tmp_path, capsys):
    """--dispersion 5 passed the parser and failed in manufacture with "spool_friction_n must be >= 0"; a model
    near a parameter's bound (discharge coefficient 0.98 <= 1) allows less."""
    from fuelhm_bench.physics.model import MAX_DISPERSION_SCALE, LoopModel, save_model

    assert MAX_DISPERSION_SCALE == 3.0  # the parser's bound (it loads no simulator)
    model = save_model(LoopModel().with_parameters({"servovalve.discharge_coefficient": 0.98}), tmp_path / "m.yaml")
    code, err = run(capsys, "simulate", "--model", str(model), "--units", "1", "--flights", "1", "--minutes", "2",
                    "--out", str(tmp_path / "o.parquet"))
    assert code == 2 and "error: --dispersion must be in [0, 0.339] for this model" in err
    assert "discharge_coefficient' parameter must be in (0, 1]. Got 1.0388 instead" in err and "Got 1 instead." in err
    assert not (tmp_path / "o.parquet").exists()


def test_out_below_a_file(tmp_path, capsys):
    blocker = tmp_path / "report.txt"
    blocker.write_text("mine")
    code, err = run(capsys, "schema", "--out", str(blocker / "schema.json"))
    assert code == 2
    assert f"Cannot write --out {blocker / 'schema.json'}: cannot create its directory" in err
    assert f"because '{blocker}' is a file, not a directory" in err
    assert blocker.read_text() == "mine"


def test_outputs_are_not_overwritten_without_force(tmp_path, capsys):
    out = tmp_path / "schema.json"
    out.write_text("user data")
    code, err = run(capsys, "schema", "--out", str(out))
    assert code == 2 and "already exists; refusing to overwrite it (pass --force" in err
    assert out.read_text() == "user data"
    code, _ = run(capsys, "schema", "--out", str(out), "--force")
    assert code == 0 and out.read_text().startswith("{")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["schema.json"]  # no temporary file left


def _interrupt(tmp_path: Path, delay_s: float) -> tuple[int, str, list[str]]:
    out = tmp_path / "flights.parquet"
    env = {**os.environ, "FUELHM_NO_PROGRESS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "fuelhm_bench.cli", "simulate", "--units", "4", "--flights", "40",
                             "--minutes", "60", "--batch-size", "4", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    return proc.returncode, err, sorted(p.name for p in tmp_path.iterdir())


def test_ctrl_c_exits_130_with_one_line_and_no_output(tmp_path):
    """SIGINT during the simulation (imports done, numba kernels running): exit 130, one line, no file."""
    code, err, files = _interrupt(tmp_path, delay_s=8.0)
    assert code == 130, err
    assert err.strip() == "fuelhm-bench: interrupted (Ctrl-C); no partial output was published."
    assert files == []


@pytest.mark.slow
@pytest.mark.parametrize("delay_s", [1.0, 2.0, 3.0, 3.5, 4.0, 4.5, 6.0, 9.0, 15.0])
def test_ctrl_c_at_any_moment(tmp_path, delay_s):
    code, err, files = _interrupt(tmp_path, delay_s)
    assert code == 130, err
    assert len(err.strip().splitlines()) == 1 and "interrupted" in err
    assert files == []


@pytest.mark.parametrize("argv", [
    ["evaluate", "--method", "fuelhm_baselines.trivial:NullMethod", "--scenario", "nope_scn"],
    ["leaderboard", "--config", "CONFIG"],
])
def test_a_run_refused_at_its_scenario_leaves_no_output_folder(tmp_path, capsys, argv):
    """evaluate / leaderboard created --out, then failed on the scenario and left the empty folder behind."""
    config = tmp_path / "lb.yaml"
    config.write_text("methods: [fuelhm_baselines.trivial:NullMethod]\nscenarios: [nope_scn]\n")
    out = tmp_path / "out"
    assert main([a.replace("CONFIG", str(config)) for a in argv] + ["--out", str(out)]) == 2
    assert "Unknown scenario 'nope_scn'" in capsys.readouterr().err
    assert not out.exists()
    out.mkdir()  # a folder the user made stays
    assert main([a.replace("CONFIG", str(config)) for a in argv] + ["--out", str(out)]) == 2
    assert out.is_dir()
