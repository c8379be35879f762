"""A file's type comes from its name, in one place (fuelhm_bench.filetypes): every reader refuses a name that
does not say its type (a valid CSV named decisions.txt was read as CSV), every writer of a fixed type refuses a
name that says another (YAML was written into cal.parquet)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from fuelhm_bench.errors import DataFormatError, FuelHMError, ModelFileError, ScenarioError
from fuelhm_bench.filetypes import FILE_TYPES, check_file_type, suffix_of

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name, kind, suffix", [
    ("a.parquet", "table", ".parquet"), ("A.CSV", "table", ".csv"), ("a.csv.gz", "table", ".csv.gz"),
    ("a.txt", "table", None), ("a.tar.gz", "table", None), (".csv", "table", None), ("m.yml", "yaml", ".yml"),
    ("m.yaml.bak", "yaml", None), ("c.jpg", "image", None), ("c.svg", "image", ".svg"), ("s.json", "json", ".json"),
])
def test_suffix_of(name, kind, suffix):
    assert suffix_of(name, kind) == suffix


def test_message_names_the_option_the_allowed_suffixes_and_the_given_one():
    with pytest.raises(DataFormatError) as info:
        check_file_type("out/cal.parquet", "yaml", what="model file", option="--out", writing=True)
    assert str(info.value) == ("--out out/cal.parquet: the name must end in .yaml or .yml (the model file written "
                               "there is YAML). Got '.parquet' instead.")
    with pytest.raises(DataFormatError, match=r"the decisions file 'd' from its name: the suffix must be one of "
                                              r"\.parquet, \.csv, \.csv\.gz\. Got no suffix instead\."):
        check_file_type("d", "table", what="decisions file")
    assert set(FILE_TYPES) == {"table", "yaml", "image", "json", "sqlite"}


def test_decisions_named_txt_are_not_read_as_csv(tmp_path):
    from fuelhm_bench.benchmark.exchange import read_decisions

    text = "split,unit_id,flight_index,score,alarm\ncalibration,0,0,0.1,0\ncalibration,0,1,0.2,0\ntest,0,0,1.0,1\n"
    (tmp_path / "dec.csv").write_text(text)
    assert len(read_decisions(tmp_path / "dec.csv")[0]) == 1
    (tmp_path / "dec.txt").write_text(text)
    with pytest.raises(DataFormatError, match=r"decisions file '.*dec\.txt' from its name: .* Got '\.txt' instead"):
        read_decisions(tmp_path / "dec.txt")
    (tmp_path / "dec").mkdir()
    with pytest.raises(DataFormatError, match=r"The decisions file '.*dec' is a directory, not a file\."):
        read_decisions(tmp_path / "dec")


def test_model_and_leaderboard_files_must_be_named_yaml(tmp_path):
    from fuelhm_bench.benchmark.leaderboard import LeaderboardConfig
    from fuelhm_bench.physics.model import load_model

    model = tmp_path / "model.txt"
    model.write_text("servovalve: {null_bias_a: 1e-4}\n")
    with pytest.raises(ModelFileError, match=r"model file '.*model\.txt' from its name: the suffix must be one of "
                                             r"\.yaml, \.yml\. Got '\.txt' instead"):
        load_model(model)
    board = tmp_path / "board.parquet"
    board.write_text("methods: [fuelhm_baselines.trivial:NullMethod]\nscenarios: [paper_2012]\n")
    with pytest.raises(ScenarioError, match=r"leaderboard file '.*board\.parquet' from its name"):
        LeaderboardConfig.from_yaml(board)


def test_scenario_file_must_be_named_yaml(tmp_path, capsys):
    from fuelhm_bench.cli import main
    from fuelhm_bench.scenarios import load_scenario

    path = tmp_path / "paper_2012.txt"
    shutil.copy(ROOT / "scenarios" / "paper_2012.yaml", path)
    with pytest.raises(ScenarioError, match=r"scenario file '.*paper_2012\.txt' from its name"):
        load_scenario(str(path))
    assert main(["validate", str(path)]) == 2
    assert "Got '.txt' instead" in capsys.readouterr().out


def test_flight_file_named_otherwise_is_refused(tmp_path):
    from fuelhm_bench.io import read_flights

    path = tmp_path / "flights.dat"
    path.write_text("flight_id,time_s,current_mA,position_mm\n0,0,0,0\n")
    with pytest.raises(FuelHMError, match=r"flight file '.*flights\.dat' from its name"):
        read_flights(path)
