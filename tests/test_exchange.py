"""export / score: the round trip, and a decisions file validated with clear errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.cli import main
from fuelhm_bench.errors import DataFormatError, OutputPathError
from fuelhm_bench.benchmark.exchange import export_scenario, read_decisions, score_decisions
from fuelhm_bench.methods import GUILT_COLUMNS
from fuelhm_bench.scoring import perfect_decisions


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    from conftest import _tiny_scenario

    root = tmp_path_factory.mktemp("exchange")
    scenario = _tiny_scenario(root)
    out = root / "export"
    assert main(["export", "--scenario", str(scenario), "--minutes", "2", "--raw",
                 "--out", str(out)]) == 0
    return scenario, out


def _perfect_file(out, path):
    labels = pd.read_parquet(out / "labels.parquet")
    training = pd.read_parquet(out / "training.parquet")
    test = perfect_decisions(labels).assign(split="test")
    cal = training.loc[training["split"] == "calibration", ["unit_id", "flight_index"]]
    cal = cal.assign(split="calibration", score=np.linspace(0.0, 1.0, len(cal)), alarm=False)
    pd.concat([test, cal], ignore_index=True).to_csv(path, index=False)
    return path


def test_export_writes_every_table(exported):
    _, out = exported
    training = pd.read_parquet(out / "training.parquet")
    test = pd.read_parquet(out / "test.parquet")
    labels = pd.read_parquet(out / "labels.parquet")
    assert set(training["split"]) == {"fit", "calibration"}
    assert len(test) == len(labels) == 24 and {"flight_index", "unit_id", "X1"} <= set(test.columns)
    assert test[["unit_id", "flight_index"]].equals(labels[["unit_id", "flight_index"]])
    raw = pd.read_parquet(out / "raw_test.parquet", columns=["unit_id", "flight_index", "time_s"])
    assert raw.groupby(["unit_id", "flight_index"]).ngroups == 24
    per_flight = raw.groupby(["unit_id", "flight_index"]).size()
    assert per_flight.min() > 1000  # full rate, not resampled


def test_round_trip_perfect_method_scores_100(exported, tmp_path, capsys):
    scenario, out = exported
    path = _perfect_file(out, tmp_path / "perfect.csv")
    card = score_decisions(path, scenario, flight_minutes=2.0)
    assert card.summary_score == 100.0
    assert main(["score", str(path), "--scenario", str(scenario), "--minutes", "2",
                 "--out", str(tmp_path / "tables")]) == 0
    printed = capsys.readouterr().out
    assert "summary_score" in printed and "100" in printed
    assert (tmp_path / "tables" / "headline_intervals.csv").exists()


def test_export_refuses_to_overwrite(exported):
    scenario, out = exported
    with pytest.raises(OutputPathError, match="training.parquet exists"):
        export_scenario(scenario, out, flight_minutes=2.0)


@pytest.mark.parametrize("edit, match", [
    (lambda d: d.drop(columns="score"), r"must have the columns .* Missing \['score'\]"),
    (lambda d: d.assign(extra=1), r"unknown column\(s\) \['extra'\]"),
    (lambda d: d.assign(split=["tset"] + list(d["split"][1:])), r"line 2: column 'split' must be"),
    (lambda d: d.assign(alarm=["maybe"] + list(d["alarm"][1:])), r"line 2: column 'alarm' must be"),
    (lambda d: d.assign(score=["nan"] + list(d["score"][1:])), r"line 2: column 'score' must be a finite number. "
                                                              r"Got 'nan' instead"),
    (lambda d: d.assign(flight_index=[1.5] + list(d["flight_index"][1:])), r"'flight_index' must be an integer >= 0 "
                                                                          r"\(the flight_index of test\.parquet\)\. "
                                                                          r"Got 1\.5 instead"),
    (lambda d: d.assign(**{GUILT_COLUMNS[0]: [2.0] + [0.0] * (len(d) - 1)}), r"must be a number in \[0, 1\]. Got "
                                                                            r"2\.0 instead"),
    (lambda d: d[d["split"] == "test"], r"at least 2 'calibration' flights"),
    (lambda d: d.iloc[1:], r"1 scored flight\(s\) have no 'test' row, e.g. flight \d+ of unit \d+;"),  # 0, not np.int64
    # unit_id 0.5 gave a pandas merge message; unit 999 only "1 flight(s) missing from decisions"
    (lambda d: d.assign(unit_id=[0.5] + list(d["unit_id"][1:])), r"line 2: column 'unit_id' must be an integer >= 0 "
                                                                  r"\(the unit_id of test.parquet\). Got 0\.5 instead"),
    (lambda d: d.assign(unit_id=[999] + list(d["unit_id"][1:])), r"line 2: column 'unit_id' names 1 unit\(s\) the "
                                                                  r"scenario does not have: \[999\]; the scored fleet "
                                                                  r"has \d+ unit\(s\)"),
    (lambda d: d.assign(flight_index=[99] + list(d["flight_index"][1:])), r"line 2: column 'flight_index' must be a "
                                                                          r"scored flight of unit \d+, 0 to \d+\. Got 99"),
    # calibration rows were only counted (>= 2): a file could set every *_thr threshold itself
    (lambda d: pd.concat([d[d["split"] == "test"], d[d["split"] == "calibration"].iloc[:2]]),
     r"\d+ of the calibration flights of training.parquet: \d+ flights of units \d+ to \d+ have no 'calibration' "
     r"row"),
    (lambda d: d.assign(unit_id=np.where(d["split"] == "calibration", 12345, d["unit_id"])),
     r"line \d+: a 'calibration' row names flight 0 of unit 12345, which is not one of the calibration flights"),
    (lambda d: pd.concat([d, d[d["split"] == "calibration"].iloc[:1]]), r"line \d+: a 'calibration' row repeats"),
    (lambda d: pd.concat([d, d[d["split"] == "test"].iloc[:1]]), r"line \d+: a 'test' row repeats flight 0 of unit 0"),
    (lambda d: pd.concat([d, d[d["split"] == "test"].assign(split="calibration")]),  # the scored flights' scores
     r"line \d+: a 'calibration' row names flight 0 of unit 0, which is not one"),
    # guilt: the sum and the rule with the line (it said "an invalid guilt at flight 12 of unit 0")
    (lambda d: d.assign(alarm=1, **{GUILT_COLUMNS[0]: 0.5, GUILT_COLUMNS[1]: 0.0}).pipe(
        lambda e: e.assign(**{c: 0.0 for c in GUILT_COLUMNS[2:]})),
     r"line 2: columns guilt_<mode> must sum to 1 on an alarm \(or all 0: uniform guilt\), within 0.001. Got a "
     r"sum of 0.5"),
    (lambda d: d.assign(alarm=0, **{GUILT_COLUMNS[0]: 0.3}).pipe(
        lambda e: e.assign(**{c: 0.0 for c in GUILT_COLUMNS[1:]})),
     r"line 2: columns guilt_<mode> must sum to 0 or 1 without an alarm, within 0.001. Got a sum of 0.3"),
])
def test_bad_decisions_file_is_named(exported, tmp_path, edit, match):
    scenario, out = exported
    good = pd.read_csv(_perfect_file(out, tmp_path / "good.csv"))
    bad = tmp_path / "bad.csv"
    edit(good).to_csv(bad, index=False)
    with pytest.raises(DataFormatError, match=match) as err:
        score_decisions(bad, scenario, flight_minutes=2.0)
    assert "bad.csv" in str(err.value) and "np." not in str(err.value)


def test_cli_says_why_a_kpi_is_undefined(exported, tmp_path, capsys):
    """Every score equal: 'fpr_paper_def_thr nan' was printed with no reason."""
    scenario, out = exported
    flat = pd.read_csv(_perfect_file(out, tmp_path / "good.csv")).assign(score=0.0, alarm=0)
    flat.to_csv(tmp_path / "flat.csv", index=False)
    assert main(["score", str(tmp_path / "flat.csv"), "--scenario", str(scenario), "--minutes", "2"]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("fpr_paper_def_thr"))
    assert "nan  (undefined: no detection: FP + FD = 0 at A = 2" in line and "are all equal (sigma = 0)" in line


def test_missing_file_and_cli_error(tmp_path, capsys):
    with pytest.raises(DataFormatError, match="no such decisions file"):
        read_decisions(tmp_path / "none.csv")
    assert main(["score", str(tmp_path / "none.csv"), "--scenario", "paper_2012"]) == 2
    assert "no such decisions file" in capsys.readouterr().err


@pytest.mark.slow  # builds the surrogate's (small) knowledge
def test_round_trip_surrogate_fidelity(tmp_path):
    from conftest import _tiny_scenario

    from fuelhm_bench.envs import KnowledgeSize

    scenario = _tiny_scenario(tmp_path)
    kw = {"fidelity": "surrogate", "flight_minutes": 2.0, "knowledge_size": KnowledgeSize.small()}
    export_scenario(scenario, tmp_path / "out", **kw)
    test = pd.read_parquet(tmp_path / "out" / "test.parquet")
    assert len(test) == 24 and np.isfinite(test["X1"]).all()
    path = _perfect_file(tmp_path / "out", tmp_path / "perfect.csv")
    assert score_decisions(path, scenario, **kw).summary_score == 100.0


def test_physics_labels_carry_the_faults_outside_the_seven_modes(tmp_path):
    """At physics fidelity the exported labels had no unknown_fault / onset_unknown: flights with a fault
    outside the seven modes were scored as healthy (robustness_drift: the perfect decisions scored 87.05,
    and 100 at surrogate fidelity). Both fidelities now label the same schedules the same way."""
    import yaml

    from conftest import _tiny_scenario

    from fuelhm_bench.benchmark.exchange import EXPORT_LABEL_COLUMNS, scenario_tables
    from fuelhm_bench.envs import KnowledgeSize

    path = _tiny_scenario(tmp_path, "tinyunknown", base="robustness_drift")
    data = yaml.safe_load(path.read_text())
    data.update(degradations=[], healthy_probability=1.0,
                unknown_faults=[{"effect": "lvdt_lag", "parameters": {"time_constant_s": 0.05}, "probability": 1.0,
                                 "onset_min": 2, "onset_max": 4}])
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    export_scenario(path, tmp_path / "out", fidelity="physics", flight_minutes=2.0)
    labels = pd.read_parquet(tmp_path / "out" / "labels.parquet")
    assert list(labels.columns) == list(EXPORT_LABEL_COLUMNS)
    assert (labels["unknown_fault"] == "lvdt_lag").all() and labels["onset_unknown"].between(2, 4).all()
    pd.testing.assert_frame_equal(labels, scenario_tables(path, fidelity="surrogate", flight_minutes=2.0,
                                                  knowledge_size=KnowledgeSize.small()).labels,
                                  check_dtype=False)
    card = score_decisions(_perfect_file(tmp_path / "out", tmp_path / "perfect.csv"), path, fidelity="physics",
                           flight_minutes=2.0)
    assert card.summary_score == 100.0


def test_csv_lines_count_blank_lines_and_rounded_guilt_is_accepted(exported, tmp_path):
    """pandas skips blank lines, so an error named the line above the bad one; and probabilities written
    rounded (0.3333 x 3) were refused by the harness's 1e-6 tolerance."""
    scenario, out = exported
    good = pd.read_csv(_perfect_file(out, tmp_path / "good.csv"))
    text = good.to_csv(index=False).splitlines()
    text[5] = text[5].replace("test", "tset", 1)
    bad = tmp_path / "blank.csv"
    bad.write_text("\n".join(text[:3] + [""] + text[3:]) + "\n")  # a blank line 4; the bad row is on line 7
    with pytest.raises(DataFormatError, match=r"blank.csv, line 7: column 'split' must be"):
        score_decisions(bad, scenario, flight_minutes=2.0)
    alarm = good["alarm"].astype(bool)
    guilt = good[list(GUILT_COLUMNS)].to_numpy()
    rounded = np.where(guilt == 1.0, 0.9995, guilt)  # within 1e-3 of 1: divided by its sum
    good.loc[alarm, list(GUILT_COLUMNS)] = rounded[alarm.to_numpy()]
    good.to_csv(tmp_path / "rounded.csv", index=False)
    assert score_decisions(tmp_path / "rounded.csv", scenario, flight_minutes=2.0).summary_score == 100.0


def test_score_checks_the_export_it_was_given(exported, tmp_path, capsys):
    """A wrong --seed with the same number of units has the same flight keys: 'score' scored the decisions
    against another fleet with exit 0 (35.86 instead of 27.0). export.json now identifies the flights."""
    import json

    scenario, out = exported
    manifest = json.loads((out / "export.json").read_text())
    assert manifest["scenario"] == "tiny-v3" and manifest["flight_minutes"] == 2.0 and len(manifest["tables_digest"]) == 16
    path = _perfect_file(out, tmp_path / "perfect.csv")
    assert main(["score", str(path), "--scenario", str(scenario), "--minutes", "2", "--exported", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"tables {manifest['tables_digest']}" in printed and "seed " in printed
    assert main(["score", str(path), "--scenario", str(scenario), "--minutes", "2", "--seed", "5",
                 "--exported", str(out)]) == 2
    err = capsys.readouterr().err
    assert "export.json: these decisions were made on other flights than the ones scored: seed" in err
    assert "there, 5 here" in err and "tables_digest" in err
    assert main(["score", str(path), "--scenario", str(scenario), "--minutes", "2",
                 "--exported", str(tmp_path)]) == 2
    assert f"--exported {tmp_path}: no export.json there" in capsys.readouterr().err


def test_tables_digest_is_the_same_for_equal_tables_in_any_backend():
    """export.json's table digest is a canonical form: equal tables digest alike whether their text is
    object or Arrow-backed, their numbers NumPy or nullable, their NaNs of any bit pattern (an export
    and a score made with different pandas versions agree), and any changed value changes it."""
    import hashlib

    from fuelhm_bench.benchmark.exchange import _digest_table

    def digest(table):
        h = hashlib.sha256()
        _digest_table(h, table)
        return h.hexdigest()

    odd_nan = np.frombuffer(np.array([0x7FF8000000000001], dtype="<u8").tobytes(), dtype="<f8")[0]
    base = pd.DataFrame({"unit_id": np.array([0, 0, 1], dtype=np.int64), "X1": [1.5, np.nan, -0.0],
                         "X1_valid": [True, False, True], "quality_reason": ["", "X1: none", ""],
                         "unknown_fault": ["", None, "rod_friction"]})
    same = [
        base.astype({"quality_reason": "string", "unknown_fault": "string"}),
        base.astype({"unit_id": "Int64", "X1": "Float64", "X1_valid": "boolean"}),
        base.assign(X1=[1.5, odd_nan, -0.0]),
        base.astype({"quality_reason": "string[pyarrow]", "unknown_fault": "string[pyarrow]"}),
    ]
    for other in same:
        assert digest(other) == digest(base), other.dtypes.to_dict()
    odd = base.assign(X1=[1.5, odd_nan, -0.0])
    before = odd["X1"].to_numpy().tobytes()
    digest(odd)
    assert odd["X1"].to_numpy().tobytes() == before  # the table itself is not rewritten (its NaN kept)
    changed = [base.assign(X1=[1.5, np.nan, 0.0]), base.assign(quality_reason=["", "X1: none ", ""]),
               base.assign(unit_id=[0, 1, 1]), base.rename(columns={"X1": "Y1"}), base.iloc[:2],
               base.assign(unknown_fault=["", "", "rod_friction"])]
    assert len({digest(t) for t in changed} | {digest(base)}) == len(changed) + 1
