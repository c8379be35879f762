"""Robustness measured: the drift sweep (one parameter at a time, several magnitudes) on a tiny setting."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.benchmark.drift_sweep import DriftSweep, run_drift_sweep
from fuelhm_bench.errors import ParameterError
from fuelhm_bench.methods import RandomMethod
from fuelhm_bench.scoring import degradation_summary, drift_sweep_table


def test_sweep_declaration_is_validated():
    assert DriftSweep().magnitudes == (0.05, 0.1, 0.2)
    with pytest.raises(ParameterError, match="at least three distinct"):
        DriftSweep(magnitudes=(0.1, 0.2))
    with pytest.raises(ParameterError, match="> -1 for relative"):
        DriftSweep(magnitudes=(-1.5, 0.1, 0.2))
    with pytest.raises(ParameterError, match="'change' parameter of DriftSweep"):
        DriftSweep(change="scaled")
    with pytest.raises(ParameterError, match="'parameters' parameter"):
        DriftSweep(parameters="fluid.supply_rise_at_100pct_pa")


def test_summary_finds_the_first_degrading_drift_per_parameter():
    sweep = pd.DataFrame({"parameter": ["a"] * 3 + ["b"] * 3, "magnitude": [-0.2, 0.05, -0.1, 0.1, 0.2, 0.3],
                          "delta_fpr": [0.2, 0.0, 0.01, 0.0, 0.01, 0.02],
                          "delta_fnr": [0.0, 0.0, 0.07, 0.0, 0.0, 0.04]})
    s = degradation_summary(sweep, tolerance=0.05).set_index("parameter")
    assert s.loc["a", "degrades_at"] == -0.1 and s.loc["a", "by"] == "fnr"
    assert np.isnan(s.loc["b", "degrades_at"]) and "neither FPR nor FNR" in s.loc["b", "summary"]
    assert s.loc["a", "max_delta_fpr"] == 0.2
    with pytest.raises(ParameterError, match="tolerance"):
        degradation_summary(sweep, tolerance=5)


def test_sweep_table_rejects_bad_keys():
    with pytest.raises(ParameterError, match="non-empty mapping"):
        drift_sweep_table(None, {})


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    import yaml
    from conftest import _tiny_scenario

    path = _tiny_scenario(tmp_path_factory.mktemp("sweep"), "tinysweep", base="paper_2012")
    data = yaml.safe_load(path.read_text())
    data["fleet"]["units"], data["mission"]["duration_min"] = 2, 3.0  # smaller still: 3-minute flights
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.mark.slow
def test_a_method_blind_to_the_data_shows_no_change(tiny):
    sweep = DriftSweep(parameters=("fluid.supply_rise_at_100pct_pa",), magnitudes=(-0.1, -0.3, -0.5))
    result = run_drift_sweep(RandomMethod(alarm_probability=0.3), tiny, sweep, doe_units=1)
    t = result.table
    assert t["magnitude"].tolist() == [-0.1, -0.3, -0.5] and len(result.runs) == 3
    # Same units, same flights, same seeds: the random method decides the same; only drift could differ.
    assert (t["delta_fpr"] == 0).all() and (t["delta_fnr"] == 0).all()
    assert np.isnan(result.summary["degrades_at"].iloc[0])
    assert "| fluid.supply_rise_at_100pct_pa | -0.5 |" in result.to_markdown()


@pytest.mark.slow
def test_sweep_measures_fpr_and_fnr_changes_of_a_real_method(tiny):
    from fuelhm_baselines.paper_mahalanobis import PaperMahalanobis

    sweep = DriftSweep(parameters=("fluid.supply_rise_at_100pct_pa",), magnitudes=(-0.05, -0.25, -0.5),
                       tolerance=0.05)
    result = run_drift_sweep(PaperMahalanobis(a=2.0), tiny, sweep, doe_units=1)
    t = result.table.set_index("magnitude")
    for col in ("fpr", "fnr", "balanced_accuracy"):
        np.testing.assert_allclose(t[f"delta_{col}"], t[f"{col}_drifted"] - t[f"{col}_nominal"])
    # Halving the supply pressure rise slows the rod everywhere: healthy flights look faulty.
    assert t.loc[-0.5, "delta_fpr"] > 0.05
    s = result.summary.iloc[0]
    assert s["degrades_at"] in (-0.05, -0.25, -0.5) and "fpr" in s["by"]
    with pytest.raises(ParameterError, match=r"^DriftSweep.parameters fluid.nonexistent_pa: must be a parameter path"):
        run_drift_sweep(PaperMahalanobis(), tiny, DriftSweep(parameters=("fluid.nonexistent_pa",)), doe_units=1)


def test_drift_sweep_command(tiny, tmp_path):
    from fuelhm_bench.cli import main

    out = tmp_path / "sweep"
    assert main(["drift-sweep", "--method", "fuelhm_bench.methods:RandomMethod", "--param", "alarm_probability=0.2",
                 "--scenario", str(tiny), "--parameters", "servovalve.spool_time_constant_s",
                 "--magnitudes", "0.1,0.2,0.4", "--doe-units", "1", "--out", str(out)]) == 0
    table = pd.read_csv(out / "drift_sweep.csv")
    assert table["magnitude"].tolist() == [0.1, 0.2, 0.4]
    # A data-blind method decides the same on the same flights: the drift cannot move its rates.
    assert (table["delta_fpr"] == 0).all() and (table["delta_fnr"] == 0).all()
    assert "neither FPR nor FNR" in pd.read_csv(out / "drift_summary.csv")["summary"].iloc[0]
    assert main(["drift-sweep", "--method", "fuelhm_bench.methods:RandomMethod", "--scenario", str(tiny),
                 "--parameters", "servovalve.spool_time_constant_s", "--magnitudes", "0.1,0.2",
                 "--out", str(tmp_path / "bad")]) == 2


@pytest.mark.parametrize("argv, name", [
    (["drift-sweep", "--method", "fuelhm_baselines.trivial:NullMethod", "--scenario", "paper_2012", "--parameters",
      "fluid.supply_rise_at_100pct_pa"], "drift_sweep.md"),
    (["fidelity", "--scenario", "paper_2012"], "table.md"),
    (["itl", "--scenario", "paper_2012", "--units", "1", "--minutes", "3", "--healthy-units", "3",
      "--healthy-flights", "4", "--intensities", "0.5,1", "--jobs", "1"], "itl.csv"),  # refused when publishing
])
def test_commands_do_not_replace_the_users_files(tmp_path, capsys, argv, name):
    """itl, fidelity and drift-sweep replaced a same-named file the user had in --out, without --force."""
    from fuelhm_bench.cli import main

    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_text("the user's notes")
    code = main([*argv, "--out", str(out)])
    assert code == 2
    assert f"already holds {name}, not written by fuelhm-bench" in capsys.readouterr().err
    assert (out / name).read_text() == "the user's notes"


@pytest.mark.parametrize("extra, expected", [
    (["--parameters", "servovalve.null_bias_drift_a"],  # said "Scenario.drift[0].parameter must be ..."
     "error: --parameters servovalve.null_bias_drift_a: must be a parameter that drift may change; not "
     "servovalve.null_bias_drift_a, because degradation mode null_bias_drift acts on it"),
    (["--parameters", "fluid.supply_rise_at_100pct_pa", "--change", "absolute", "--magnitudes", "1e20,2e20,3e20"],
     "error: --magnitudes 1e+20 (absolute, on fluid.supply_rise_at_100pct_pa): must be in [-5.15e+06, 1.03e+07]"),
    (["--parameters", "servovalve.null_bias_a", "--change", "absolute", "--magnitudes", "1e-4,2e-4,1.6e-3"],
     "error: --magnitudes 0.0016 (absolute, on servovalve.null_bias_a): must be in [-0.00025, 0.0004]"),
    (["--parameters", "fluid.supply_rise_at_100pct_pa", "--magnitudes", "0.1,0.2"],
     "error: --magnitudes must be at least three distinct non-zero numbers. Got 0.1,0.2 instead."),
])
def test_drift_sweep_names_its_options_and_checks_them_first(tmp_path, capsys, extra, expected):
    """Refused before anything runs or is created, in the command line's terms, by the scenario's drift rules."""
    from fuelhm_bench.cli import main

    out = tmp_path / "out"
    code = main(["drift-sweep", "--method", "fuelhm_baselines.trivial:NullMethod", "--scenario", "paper_2012",
                 *extra, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and expected in err, err
    assert "Scenario." not in err and "DriftSweep" not in err
    assert not out.exists()


def test_itl_names_its_options_when_the_healthy_fleet_is_too_small(tmp_path, capsys):
    from fuelhm_bench.cli import main

    assert main(["itl", "--scenario", "paper_2012", "--healthy-units", "2", "--healthy-flights", "2",
                 "--out", str(tmp_path / "k")]) == 2
    assert "--healthy-units x --healthy-flights must give at least 11 healthy flights" in capsys.readouterr().err
