"""Velocity-gain plots (paper Figs. 4, 5, 8) render with the Agg backend."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.indicators import indicators_from_curve, velocity_gain_curve, velocity_points
from fuelhm_bench.indicators.plot import plot_velocity_gain, velocity_gain_figure
from fuelhm_bench.testing.indicators import DualGainCurve, synthetic_flight


@pytest.fixture(scope="module")
def extracted():
    f = synthetic_flight(n_excursions=150, seed=51)
    i, v = velocity_points(f.time_s, f.current_ma, f.position_mm)
    curve = velocity_gain_curve(f.time_s, f.current_ma, f.position_mm)
    return i, v, curve, indicators_from_curve(curve)


def test_points_curve_and_annotations(extracted, tmp_path):
    i, v, curve, result = extracted
    fig = velocity_gain_figure(i, v, curve, result, title="flight 51")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "Control current (mA)"
    assert ax.get_ylabel() == "Cylinder velocity (mm/s)"
    # Raw points: one scatter collection with the (subsampled) points.
    offsets = ax.collections[0].get_offsets()
    assert 0 < len(offsets) <= 50_000
    # Local-mean curve: passes through the bin means.
    line = next(ln for ln in ax.lines if ln.get_label() == "local mean")
    used = curve.count >= 1
    np.testing.assert_allclose(line.get_ydata(), curve.mean_velocity_mm_s[used])
    # Fig. 5 annotations: slope-change markers, Inb and I0 lines, gain labels, fit.
    texts = {t.get_text().strip() for t in ax.texts}
    assert {"(X1, Y1)", "(X2, Y2)", "Inb", "I0"} <= texts
    assert any(t.startswith("G_in = ") for t in texts)
    assert any(t.startswith("G_null = ") for t in texts)
    markers = [ln for ln in ax.lines if ln.get_marker() == "o"]
    xs = sorted(float(ln.get_xdata()[0]) for ln in markers)
    assert xs == pytest.approx(sorted([result.values["X1"], result.values["X2"]]))
    assert any(ln.get_label() == "piecewise-linear fit" for ln in ax.lines)
    path = tmp_path / "fig5.png"
    fig.savefig(path, dpi=60)
    assert path.stat().st_size > 5_000


def test_overlay_of_degraded_curves(tmp_path):
    curves, results = [], []
    for drift in (0.0, 0.8, 1.6):  # paper Fig. 8 (a): null-bias drift
        f = synthetic_flight(DualGainCurve(inb_ma=0.5 + drift), n_excursions=120, seed=52)
        c = velocity_gain_curve(f.time_s, f.current_ma, f.position_mm)
        curves.append(c)
        results.append(indicators_from_curve(c))
    fig = Figure()
    ax = fig.add_subplot()
    plot_velocity_gain(ax, None, None, curves, results, labels=["0 %", "50 %", "100 %"])
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend[:3] == ["0 %", "50 %", "100 %"]
    assert not ax.collections  # no raw points requested
    assert not any(t.get_text().startswith("G_") for t in ax.texts)  # no text clutter
    fig.savefig(tmp_path / "fig8.png", dpi=60)


def test_annotations_skip_invalid_indicators(extracted):
    i, v, curve, result = extracted
    values = dict(result.values, X2=float("nan"), Y2=float("nan"))
    fig = Figure()
    ax = fig.add_subplot()
    plot_velocity_gain(ax, i, v, curve, values)
    texts = {t.get_text().strip() for t in ax.texts}
    assert "(X1, Y1)" in texts and "(X2, Y2)" not in texts


def test_plot_argument_errors(extracted):
    i, v, curve, result = extracted
    ax = Figure().add_subplot()
    with pytest.raises(ParameterError, match="'labels' parameter of plot_velocity_gain"):
        plot_velocity_gain(ax, None, None, [curve, curve], labels=["one"])
    with pytest.raises(ParameterError, match="'indicators' parameter"):
        plot_velocity_gain(ax, None, None, [curve, curve], [result])
    with pytest.raises(ParameterError, match="'current' and 'velocity' parameters"):
        plot_velocity_gain(ax, i, None, curve)
    with pytest.raises(ParameterError, match="'velocity' parameter .* shape"):
        plot_velocity_gain(ax, i, v[:-1], curve)
    with pytest.raises(ParameterError, match="'curve' parameter"):
        plot_velocity_gain(ax, i, v, "not a curve")
