"""The evaluation runner and the evaluate / paper commands on a tiny scenario."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from fuelhm_bench.cli import main
from fuelhm_bench.errors import MethodError
from fuelhm_bench.evaluation import load_method, parse_params, run_method, scenario_data
from fuelhm_bench.methods import BaseMethod, Decision
from sizes import DOE_UNITS


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    from conftest import _tiny_scenario

    path = _tiny_scenario(tmp_path_factory.mktemp("sc"))
    data, _ = scenario_data(path, doe_units=DOE_UNITS)
    return path, data


class Raises(BaseMethod):
    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        raise RuntimeError("boom in fit")

    def _decide(self, row):
        return Decision.no_alarm(0.0)


class Hangs(BaseMethod):
    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        time.sleep(60)

    def _decide(self, row):
        return Decision.no_alarm(0.0)


class BadGuilt(BaseMethod):
    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        pass

    def _decide(self, row):
        return Decision(1.0, True, np.full(7, 0.5))


def test_data_split_and_no_label_leak(tiny):
    _, data = tiny
    assert set(data.fit_indicators["unit_id"]).isdisjoint(set(data.calibration_indicators["unit_id"]))
    assert not any(c.startswith(("intensity_", "onset_", "max_intensity_")) for c in data.test_indicators.columns)
    assert len(data.test_indicators) == len(data.test_labels) == 24


def test_run_method_reports_failures_without_raising(tiny):
    _, data = tiny
    ok = run_method(load_method("baselines.paper_mahalanobis:PaperMahalanobis"), data, timeout_s=120)
    assert ok.ok and len(ok.decisions) == 24 and np.all(np.isfinite(ok.healthy_scores))
    err = run_method(Raises(), data, timeout_s=60)
    assert err.status == "error" and "boom in fit" in err.message
    t0 = time.perf_counter()
    hang = run_method(Hangs(), data, timeout_s=2)
    assert hang.status == "timeout" and time.perf_counter() - t0 < 15
    bad = run_method(BadGuilt(), data, timeout_s=60)
    assert bad.status == "invalid" and "guilt" in bad.message.lower()


def test_load_method_errors():
    with pytest.raises(MethodError, match="must look like"):
        load_method("baselines.trivial")
    with pytest.raises(MethodError, match="Cannot import"):
        load_method("no_such_pkg.mod:X")
    with pytest.raises(MethodError, match="has no class 'Nope'.*NullMethod"):
        load_method("baselines.trivial:Nope")
    assert parse_params(["a=2", "cv=loo", "flag=true"]) == {"a": 2, "cv": "loo", "flag": True}


def test_evaluate_command(tiny, tmp_path, capsys):
    path, _ = tiny
    out = tmp_path / "eval"
    code = main(["evaluate", "--method", "baselines.paper_mahalanobis:PaperMahalanobis", "--param", "a=3",
                 "--method", "baselines.trivial:NullMethod", "--method", "nowhere:X",
                 "--scenario", str(path), "--out", str(out)])
    assert code == 3  # one method could not be loaded; the others are kept
    summary = json.loads((out / "summary.json").read_text())
    status = {m["method"]: m["status"] for m in summary["methods"]}
    assert status == {"nowhere:X": "error", "baselines.paper_mahalanobis:PaperMahalanobis": "ok",
                      "baselines.trivial:NullMethod": "ok"}
    paper = next(m for m in summary["methods"] if m["method"].startswith("baselines.paper"))
    assert paper["params"]["a"] == "3"
    assert (out / "baselines.paper_mahalanobis_PaperMahalanobis" / "table_v_detection.csv").exists()
    assert "Evaluation on" in (out / "report.md").read_text()


def test_paper_command_small(tiny, tmp_path, capsys):
    path, _ = tiny
    out = tmp_path / "paper"
    assert main(["paper", "--scenario", str(path), "--doe-units", "1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "TABLE IV" in text and "TABLE V" in text and "TABLE VI" in text
    for name in ("table_iv.csv", "table_v.csv", "table_vi.csv", "report.md", "fig4_curve.png",
                 "fig5_indicators.png", "fig8a_drift.png", "fig8b_leak.png", "fig10_scores.png"):
        assert (out / name).exists(), name
    assert "Where and why the numbers differ" in (out / "report.md").read_text()


def test_evaluate_reports_robustness_under_drift(tmp_path, tiny_scenario):
    path = tiny_scenario(tmp_path, "tinydrift", base="robustness_drift")
    out = tmp_path / "eval"
    assert main(["evaluate", "--method", "baselines.paper_mahalanobis:PaperMahalanobis", "--scenario", str(path),
                 "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    kpis = summary["methods"][0]["kpis"]
    assert kpis["robustness"] is not None and 0.0 < kpis["robustness"] < 2.0
    assert (out / "baselines.paper_mahalanobis_PaperMahalanobis" / "robustness.csv").exists()
