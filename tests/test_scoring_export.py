"""Tests of the exports (CSV, Markdown, LaTeX) and of the Fig. 10 figure."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.errors import OutputPathError, ParameterError
from fuelhm_bench.scoring import (plot_score_distributions, save_figure, score_run, to_latex,
                                  to_markdown, write_tables)

from test_scoring_run import decisions, fleet_labels, make_run


@pytest.fixture(scope="module")
def card():
    labels = fleet_labels()
    rng = np.random.default_rng(0)
    alarm = rng.random(len(labels)) < 0.5
    return score_run(make_run(labels, decisions(labels, alarm, score=rng.normal(2, 2, 70))))


def test_markdown_table():
    df = pd.DataFrame({"mode": ["a|b", "c"], "rate": [0.123456, np.nan], "n": [3, 4],
                       "ok": [True, False]})
    md = to_markdown(df).splitlines()
    assert md[0] == "| mode | rate | n | ok |" and md[1] == "|---|---|---|---|"
    assert md[2] == r"| a\|b | 0.1235 | 3 | True |" and md[3] == "| c | NaN | 4 | False |"


def test_latex_escapes_and_aligns():
    df = pd.DataFrame({"mode_id": ["50%", "x&y"], "fpr": [0.5, 0.25]})
    tex = to_latex(df, float_format=".3g", caption="Table V", label="tab:v")
    assert r"\begin{tabular}{lr}" in tex and r"\caption{Table V}" in tex
    assert r"mode\_id & fpr \\" in tex and r"50\% & 0.5 \\" in tex and r"x\&y & 0.25 \\" in tex
    assert tex.strip().endswith(r"\end{table}")


def test_latex_does_not_depend_on_jinja2(monkeypatch):
    """One writer: the same bytes whether or not the optional jinja2 (pandas' to_latex) is importable."""
    import importlib.util
    import sys

    df = pd.DataFrame({"mode": ["a_b", "c"], "rate": [0.123456, np.nan], "n": [3, 4], "ok": [True, False]})
    before = to_latex(df, caption="x", label="t")
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "jinja2" else real(name, *a))
    monkeypatch.setitem(sys.modules, "jinja2", None)
    assert to_latex(df, caption="x", label="t") == before
    assert r"a\_b & 0.1235 & 3 & True \\" in before and r"c & NaN & 4 & False \\" in before


def test_write_tables_all_formats(card, tmp_path):
    paths = write_tables(card, tmp_path / "out")
    names = {p.name for p in paths}
    assert "table_v_detection.csv" in names and "confusion.md" in names
    assert "table_vi_diagnosis.tex" in names and len(paths) == 3 * len(card.tables())
    back = pd.read_csv(tmp_path / "out" / "table_v_detection.csv")
    np.testing.assert_allclose(back["fpr_standard"], card.detection["fpr_standard"])
    conf = pd.read_csv(tmp_path / "out" / "confusion.csv")
    assert conf.columns[0] == "true_condition" and conf["true_condition"].iloc[0] == "healthy"
    with pytest.raises(OutputPathError, match="overwrite=True"):
        write_tables(card, tmp_path / "out", formats=("csv",))
    assert write_tables(card, tmp_path / "out", formats=("csv",), overwrite=True)
    with pytest.raises(ParameterError, match=r"Got \['xlsx'\] instead"):
        write_tables(card, tmp_path / "x", formats=("xlsx",))


def test_score_distribution_figure(tmp_path):
    labels = fleet_labels()
    rng = np.random.default_rng(0)
    score = rng.normal(0, 1, 70) + 8 * (labels.filter(like="intensity_").sum(axis=1)).to_numpy()
    run = make_run(labels, decisions(labels, score > 2, score=score))
    fig = plot_score_distributions(run)
    ax = fig.axes[0]
    assert len([line for line in ax.lines if line.get_linestyle() == "--"]) == 5  # thresholds
    labels_text = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("healthy (training)" in t for t in labels_text)
    assert any("internal_leakage" in t for t in labels_text)
    path = save_figure(fig, tmp_path / "fig10.png")
    assert path.stat().st_size > 1000 and path.read_bytes()[:4] == b"\x89PNG"
    import matplotlib.pyplot as plt

    save_figure(fig, tmp_path / "fig10.svg", close=True)  # not a pyplot figure: closing is harmless
    assert (tmp_path / "fig10.svg").stat().st_size > 1000
    pyplot_fig, _ = plt.subplots()  # e.g. plot_reliability's figure, drawn once per leaderboard entry
    save_figure(pyplot_fig, tmp_path / "a.png")
    assert plt.fignum_exists(pyplot_fig.number)  # kept by default: the caller may still draw on it
    save_figure(pyplot_fig, tmp_path / "b.png", close=True)  # batch writers release each figure
    assert not plt.fignum_exists(pyplot_fig.number)
