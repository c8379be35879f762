"""Output files of every command go through one check (fuelhm_bench.cli._common.check_output): named for what is
written there, and never one of the command's own input files, even with --force. Both refused before any work."""

from __future__ import annotations

import os

import pytest

from fuelhm_bench.cli import main


def run(capsys, *argv) -> tuple[int, str]:
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr().err


@pytest.mark.parametrize("argv, option, name, allowed", [
    (["calibrate", "flights.parquet", "--out", "cal.parquet"], "--out", "cal.parquet", ".yaml or .yml"),
    (["calibrate", "flights.parquet", "--out", "cal.yaml", "--plot", "c.jpg"], "--plot", "c.jpg", ".png, .pdf or .svg"),
    (["plot-curve", "flights.parquet", "--out", "c.jpg"], "--out", "c.jpg", ".png, .pdf or .svg"),
    (["indicators", "flights.parquet", "--out", "ind.txt"], "--out", "ind.txt", ".parquet, .csv or .csv.gz"),
    (["simulate", "--units", "1", "--flights", "1", "--out", "f.txt"], "--out", "f.txt", ".parquet, .csv or .csv.gz"),
    (["sweep", "--out", "s.yaml"], "--out", "s.yaml", ".parquet, .csv or .csv.gz"),
    (["schema", "--out", "schema.yaml"], "--out", "schema.yaml", ".json"),
    (["evaluate", "--method", "fuelhm_baselines.trivial:NullMethod", "--scenario", "paper_2012", "--out", "o",
      "--store", "store.csv"], "--store", "store.csv", ".sqlite, .sqlite3 or .db"),
])
def test_output_named_for_another_type_is_refused_first(tmp_path, capsys, monkeypatch, argv, option, name, allowed):
    """calibrate wrote YAML into cal.parquet and accepted --plot c.jpg, while plot-curve refused c.jpg."""
    monkeypatch.chdir(tmp_path)
    code, err = run(capsys, *argv)
    assert code == 2
    assert f"error: {option} {name}: the name must end in {allowed} (the " in err, err
    assert sorted(os.listdir(tmp_path)) == []  # refused before anything was read or written


def _flight_file(path):
    import numpy as np
    import pandas as pd

    t = np.arange(0.0, 60.0, 0.01)
    pd.DataFrame({"flight_id": 0, "time_s": t, "current_mA": 5 * np.sin(t), "position_mm": 30 + np.cumsum(
        np.sin(t)) * 0.01}).to_csv(path, index=False)
    return path


def test_indicators_never_replace_their_input_even_with_force(tmp_path, capsys):
    """'indicators x.csv --out x.csv --force' replaced the flights with the indicator table."""
    flights = _flight_file(tmp_path / "flights.csv")
    before = flights.read_bytes()
    (tmp_path / "link.csv").symlink_to(flights)
    for out in (flights, tmp_path / "link.csv", tmp_path / "." / "flights.csv"):
        code, err = run(capsys, "indicators", str(flights), "--out", str(out), "--force")
        assert code == 2
        assert f"error: Cannot write --out {out}: it is the input file FLIGHTS ({flights}); an input is never " \
               f"overwritten, even with --force." in err
    assert flights.read_bytes() == before


@pytest.mark.parametrize("argv, given_as", [
    (["calibrate", "{flights}", "--model", "{model}", "--out", "{model}", "--force"], "--model"),
    (["plot-curve", "{flights}", "--overlay", "{other}=x", "--out", "{other}", "--force"], "--overlay {other}=x"),
    (["discrepancy", "{flights}", "--model", "{dir}/augmented_model.yaml", "--out", "{dir}", "--force"], "--model"),
    (["score", "{dir}/headline.csv", "--scenario", "paper_2012", "--out", "{dir}", "--force"], "DECISIONS"),
])
def test_no_command_writes_over_one_of_its_inputs(tmp_path, capsys, argv, given_as):
    names = {"flights": tmp_path / "flights.csv", "model": tmp_path / "model.yaml", "other": tmp_path / "o.png",
             "dir": tmp_path / "out"}
    (tmp_path / "out").mkdir()
    for path in (names["model"], names["other"], tmp_path / "out" / "augmented_model.yaml",
                 tmp_path / "out" / "headline.csv"):
        path.write_text("the user's file\n")
    argv = [a.format(**names) for a in argv]
    code, err = run(capsys, *argv)
    assert code == 2
    assert f"it is the input file {given_as.format(**names)} (" in err and "even with --force" in err, err
    for path in (names["model"], names["other"], tmp_path / "out" / "augmented_model.yaml",
                 tmp_path / "out" / "headline.csv"):
        assert path.read_text() == "the user's file\n"


def test_score_out_is_checked_before_scoring(tmp_path, capsys):
    """score printed its KPIs, then refused --out (in Python-API terms) because it held earlier tables."""
    out = tmp_path / "tables"
    out.mkdir()
    (out / "headline.csv").write_text("earlier\n")
    code, err = run(capsys, "score", str(tmp_path / "missing.csv"), "--scenario", "paper_2012", "--out", str(out))
    assert code == 2
    assert f"error: --out {out} already holds headline.csv; refusing to overwrite (pass --force" in err
    assert (out / "headline.csv").read_text() == "earlier\n"
