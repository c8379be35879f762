"""The evaluation runner and the evaluate / paper commands on a tiny scenario."""

from __future__ import annotations

import json
import pytest

from fuelhm_bench.cli import main
from fuelhm_bench.errors import MethodError, ParameterError
from fuelhm_bench.benchmark.loading import parse_params
from fuelhm_bench.methods.loading import entry_point_problem, load_method


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    from conftest import _tiny_scenario

    path = _tiny_scenario(tmp_path_factory.mktemp("sc"))
    return path, None


def test_load_method_errors():
    with pytest.raises(MethodError, match="must look like"):
        load_method("fuelhm_baselines.trivial")
    for bad in ("a:B:C", "a.:B", "1mod:C", " mod:C", "mod:", ":C"):
        assert entry_point_problem(bad) is not None, bad
    assert entry_point_problem("fuelhm_baselines.trivial:NullMethod") is None
    assert entry_point_problem("pkg.mod:Outer.Inner") is None
    with pytest.raises(MethodError, match="Cannot import"):
        load_method("no_such_pkg.mod:X")
    with pytest.raises(MethodError, match="has no class 'Nope'.*NullMethod"):
        load_method("fuelhm_baselines.trivial:Nope")
    assert parse_params(["a=2", "cv=loo", "flag=true"]) == {"a": 2, "cv": "loo", "flag": True}
    with pytest.raises(MethodError, match="not a class"):
        load_method("fuelhm_bench.taxonomy:INDICATOR_NAMES")
    with pytest.raises(MethodError, match="neither subclasses .*BaseMethod nor defines get_params, fit, start_unit, "
                                          "decide, decide_unit"):
        load_method("fuelhm_bench.errors:MethodError")


def test_a_method_without_base_class_loads_by_entry_point(tmp_path, monkeypatch):
    """docs/methods.md section 4: a method need not inherit from BaseMethod. The Python API ran such a
    method, but ``load_method`` (the CLI, the leaderboard) refused it as "not a subclass"."""
    (tmp_path / "duck_method.py").write_text(
        "from fuelhm_bench.methods import Decision\n"
        "class Duck:\n"
        "    def __init__(self, *, a=3.0):\n        self.a = a\n"
        "    def get_params(self, deep=True):\n        return {'a': self.a}\n"
        "    def fit(self, healthy, *, knowledge=None, raw_flights=None, random_state=None):\n        return self\n"
        "    def start_unit(self, unit_id):\n        pass\n"
        "    def decide(self, row, *, raw=None):\n        return Decision(0.0, False)\n"
        "    def decide_unit(self, table, *, raw=None):\n"
        "        from fuelhm_bench.methods.base import run_unit\n        return run_unit(self, table)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    method = load_method("duck_method:Duck", {"a": 2.0})
    assert type(method).__name__ == "Duck" and method.a == 2.0
    from fuelhm_bench.methods import make_check_data

    units = make_check_data(0).units
    decisions = method.fit(units).decide_unit(units[units["unit_id"] == "check-0"])
    assert len(decisions) == 12 and not decisions["alarm"].any()


@pytest.mark.parametrize("item, match", [
    ("a=[1, 2", r"--param a=\[1, 2: the value '\[1, 2' does not parse"),
    ("a={x", r"--param a=\{x: the value"),
    ("=3", r"--param must look like NAME=VALUE"),
])
def test_unparsable_param_names_the_option(item, match):
    with pytest.raises(ParameterError, match=match):
        parse_params([item])


def test_evaluate_command(tiny, tmp_path, capsys):
    path, _ = tiny
    out = tmp_path / "eval"
    code = main(["evaluate", "--method", "fuelhm_baselines.paper_mahalanobis:PaperMahalanobis", "--param", "a=3",
                 "--method", "fuelhm_baselines.trivial:NullMethod", "--method", "nowhere:X",
                 "--scenario", str(path), "--out", str(out), "--timeout", "120"])
    assert code == 3  # one method could not be loaded; the others are kept
    (sdir,) = [d for d in out.iterdir() if d.is_dir() and d.name != "logs"]
    summary = json.loads((sdir / "summary.json").read_text())
    status = {m["method"]: m["status"] for m in summary["methods"]}
    assert status == {"nowhere:X": "error", "fuelhm_baselines.paper_mahalanobis:PaperMahalanobis": "ok",
                      "fuelhm_baselines.trivial:NullMethod": "ok"}
    assert "Cannot import the method module 'nowhere'" in next(m["message"] for m in summary["methods"]
                                                               if m["method"] == "nowhere:X")
    paper = next(m for m in summary["methods"] if m["method"].startswith("fuelhm_baselines.paper"))
    assert json.loads(paper["params"]) == {"shared": {"a": 3}}
    folder = sdir / paper["folder"].split("/")[-1]
    assert folder.name.startswith("fuelhm_baselines.paper_mahalanobis_PaperMahalanobis-")
    assert (folder / "table_v_detection.csv").exists()
    assert json.loads((folder / "result.json").read_text())["method_params"]["a"] == 3
    assert "Evaluation on" in (sdir / "report.md").read_text()
    assert (out / "results.sqlite").is_file()
    # a misspelt --param is named before anything runs: no row under the misspelt name is stored
    capsys.readouterr()
    assert main(["evaluate", "--method", "fuelhm_baselines.trivial:NullMethod", "--param", "b=3",
                 "--scenario", str(path), "--out", str(tmp_path / "eval2")]) == 2
    assert "--param b: no evaluated method has such a hyperparameter" in capsys.readouterr().err
    assert not (tmp_path / "eval2" / "results.sqlite").exists()


def test_param_reaches_a_constructor_without_default(tiny, tmp_path, monkeypatch, capsys):
    """``--param`` values the constructor takes are passed to it, so a hyperparameter without a default
    can be given on the command line (before: "Cannot build Required with {}", --param being applied
    with set_params after construction)."""
    path, _ = tiny
    (tmp_path / "required_method.py").write_text(
        "from fuelhm_baselines.paper_mahalanobis import PaperMahalanobis\n"
        "class Required(PaperMahalanobis):\n"
        "    def __init__(self, *, scale_a, **kw):\n"
        "        super().__init__(**kw)\n"
        "        self.scale_a = scale_a\n"
        "    @classmethod\n"
        "    def _get_param_names(cls):\n"
        "        return sorted(set(PaperMahalanobis._get_param_names()) | {'scale_a'})\n")
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    assert main(["evaluate", "--method", "required_method:Required", "--param", "scale_a=1e-3",
                 "--scenario", str(path), "--out", str(out), "--timeout", "120"]) == 0, capsys.readouterr().err
    (sdir,) = [d for d in out.iterdir() if d.is_dir() and d.name != "logs"]
    (folder,) = [d for d in sdir.iterdir() if d.is_dir()]
    assert json.loads((folder / "result.json").read_text())["method_params"]["scale_a"] == 0.001


def test_paper_command_small(tiny, tmp_path, capsys):
    path, _ = tiny
    out = tmp_path / "paper"
    assert main(["paper", "--scenario", str(path), "--doe-units", "1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "TABLE IV" in text and "TABLE V" in text and "TABLE VI" in text
    for name in ("table_iv.csv", "table_v.csv", "table_vi.csv", "report.md", "fig4_curve.png",
                 "fig5_indicators.png", "fig8a_drift.png", "fig8b_leak.png", "fig10_scores.png"):
        assert (out / name).exists(), name
    from fuelhm_bench.benchmark.paper_report import OUTPUT_FILES
    from fuelhm_bench.io.outputs import MANIFEST

    assert sorted(p.name for p in out.iterdir()) == sorted((*OUTPUT_FILES, MANIFEST))  # what it checks up front
    assert "Where and why the numbers differ" in (out / "report.md").read_text()


def test_evaluate_reports_robustness_under_drift(tmp_path, tiny_scenario):
    path = tiny_scenario(tmp_path, "tinydrift", base="robustness_drift")
    out = tmp_path / "eval"
    assert main(["evaluate", "--method", "fuelhm_baselines.paper_mahalanobis:PaperMahalanobis", "--scenario", str(path),
                 "--out", str(out)]) == 0
    (sdir,) = [d for d in out.iterdir() if d.is_dir() and d.name != "logs"]
    summary = json.loads((sdir / "summary.json").read_text())
    robustness = summary["methods"][0]["robustness"]
    assert robustness is not None and 0.0 < robustness < 2.0
    (folder,) = sdir.glob("fuelhm_baselines.paper_mahalanobis_PaperMahalanobis-*")
    assert (folder / "robustness.csv").exists()


def test_a_malformed_method_entry_point_is_refused_before_any_data(tmp_path, capsys, monkeypatch):
    """``--method nocolon`` is the caller's mistake: exit 2 naming the option, nothing built or written."""
    from fuelhm_bench.cli import main

    monkeypatch.setenv("FUELHM_BENCH_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "out"
    assert main(["evaluate", "--method", "fuelhm_baselines.trivial:NullMethod", "--method", "a:B:C",
                 "--scenario", "paper_2012", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--method must look like 'package.module:Class'" in err and "'a:B:C'" in err
    assert not out.exists() and not (tmp_path / "cache").exists()


@pytest.mark.parametrize("option, value, match", [
    ("--timeout", "1e300", r"argument --timeout: must be a number in \[0.001, 2.592e\+06\] s"),
    ("--memory", "1e300", r"argument --memory: must be a number in \[256, "),
    ("--cpu-time", "0", r"argument --cpu-time: must be a number in \[0.001, "),
    ("--seed", "99999999999999999999999", r"argument --seed: must be an integer in \[0, 9223372036854775807\]"),
    ("--minutes", "1e6", r"argument --minutes: must be a number in \(0, 1440\] min"),
])
def test_out_of_range_run_options_are_refused_before_anything_is_written(tmp_path, capsys, option, value, match):
    """Each was a traceback (OverflowError in a clock or in SQLite, a 44.7 GiB allocation) after the
    results store had been created."""
    import re

    out = tmp_path / "out"
    try:
        code = main(["evaluate", "--method", "fuelhm_baselines.trivial:NullMethod", "--scenario", "paper_2012",
                     "--fidelity", "surrogate", "--scale", "0.1", option, value, "--out", str(out)])
    except SystemExit as exc:  # argparse's own refusal
        code = exc.code
    assert code == 2
    assert re.search(match, capsys.readouterr().err)
    assert not out.exists()
