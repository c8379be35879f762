"""Plots of velocity-gain curves (paper Figs. 4, 5 and 8), with matplotlib.

The functions draw on a given ``Axes`` and never touch pyplot's global state, so they work
with any backend. :func:`velocity_gain_figure` builds a stand-alone
:class:`matplotlib.figure.Figure` (no pyplot), which renders with the Agg backend on
``fig.savefig(path)``; that is what scripts and tests use.

* raw points and local means (Fig. 4): ``plot_velocity_gain(ax, current, velocity, curve)``;
* indicators annotated on the curve (Fig. 5): pass ``indicators=`` (an
  :class:`~fuelhm_bench.indicators.IndicatorResult`);
* several smoothed curves overlaid (Fig. 8, curves under degradation): pass a list of curves
  and ``labels=``, with ``current=velocity=None``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.indicators.curve import VelocityGainCurve
from fuelhm_bench.indicators.fit import CurveFit
from fuelhm_bench.indicators.result import IndicatorResult

CURRENT_LABEL = "Control current (mA)"
VELOCITY_LABEL = "Cylinder velocity (mm/s)"


def _as_list(value: object, kind: type, name: str) -> list:
    if value is None:
        return []
    if isinstance(value, kind):
        return [value]
    if isinstance(value, Sequence) and all(isinstance(v, kind) or v is None for v in value):
        return list(value)
    raise ParameterError(
        f"The '{name}' parameter of plot_velocity_gain must be a {kind.__name__} or a sequence "
        f"of them. Got {type(value).__name__} instead."
    )


def _values_of(ind: IndicatorResult | Mapping[str, float]) -> tuple[dict[str, float],
                                                                  CurveFit | None]:
    if isinstance(ind, IndicatorResult):
        return dict(ind.values), ind.fit
    return {k: float(v) for k, v in ind.items()}, None


def _finite(values: Mapping[str, float], *names: str) -> bool:
    return all(name in values and math.isfinite(values[name]) for name in names)


def annotate_indicators(ax: Axes, indicators: IndicatorResult | Mapping[str, float], *,
                        color: str = "k", show_fit: bool = True, text: bool = True) -> None:
    """Mark the indicators on a velocity-gain plot (paper Fig. 5).

    Draws markers at (X1, Y1) and (X2, Y2), vertical lines at Inb and I0, the fitted
    piecewise-linear curve (dashed, when ``indicators`` carries its fit) and a label with the
    value of each gain on its segment. Invalid (NaN) indicators are skipped.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Target axes.
    indicators : IndicatorResult or mapping of str to float
        Indicator values (mA, mm/s, mm/s/mA).
    color : str, default="k"
        Colour of the annotations.
    show_fit : bool, default=True
        Draw the fitted piecewise-linear model when available.
    text : bool, default=True
        Write the names and gain values (off when several curves are overlaid).
    """
    values, fit = _values_of(indicators)
    if show_fit and fit is not None:
        lo, hi = ax.get_xlim()
        grid = np.linspace(lo, hi, 400)
        ax.plot(grid, fit.evaluate(grid), "--", color=color, lw=1.0, alpha=0.8,
                label="piecewise-linear fit")
    for xn, yn, tag in (("X1", "Y1", "(X1, Y1)"), ("X2", "Y2", "(X2, Y2)")):
        if _finite(values, xn, yn):
            ax.plot([values[xn]], [values[yn]], "o", color=color, ms=6, mfc="none", mew=1.5)
            if text:
                ax.annotate(tag, (values[xn], values[yn]), textcoords="offset points",
                            xytext=(6, -12 if tag.startswith("(X1") else 6), color=color,
                            fontsize=8)
    for name, style, y_frac in (("Inb", ":", 0.92), ("I0", "-.", 0.04)):
        if _finite(values, name):
            ax.axvline(values[name], color=color, ls=style, lw=1.0)
            if text:
                ax.text(values[name], y_frac, f" {name}", transform=ax.get_xaxis_transform(),
                        color=color, fontsize=8)
    if not text:
        return
    segments = (
        ("G_in", "X1", "Y1", -1.0),
        ("G_out", "X2", "Y2", 1.0),
    )
    for gain, xn, yn, side in segments:
        if _finite(values, gain, xn, yn):
            x = values[xn] + side * 1.5
            y = values[yn] + side * 1.5 * values[gain]
            ax.annotate(f"{gain} = {values[gain]:.3g}", (x, y), textcoords="offset points",
                        xytext=(6, -4), color=color, fontsize=8)
    if _finite(values, "G_null", "X1", "Y1", "X2", "Y2"):
        x = 0.5 * (values["X1"] + values["X2"])
        y = 0.5 * (values["Y1"] + values["Y2"])
        ax.annotate(f"G_null = {values['G_null']:.3g}", (x, y), textcoords="offset points",
                    xytext=(8, -14), color=color, fontsize=8)


def plot_velocity_gain(ax: Axes, current: np.ndarray | None, velocity: np.ndarray | None,
                       curve: VelocityGainCurve | Sequence[VelocityGainCurve] | None,
                       indicators: (IndicatorResult | Mapping[str, float]
                                    | Sequence[IndicatorResult | None] | None) = None, *,
                       labels: Sequence[str] | None = None, max_points: int = 50_000,
                       show_fit: bool = True) -> Axes:
    """Velocity-gain plot: raw points, local-mean curve(s), optional indicator annotations.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Target axes.
    current, velocity : numpy.ndarray or None
        Raw points, in mA and mm/s (e.g. from
        :func:`~fuelhm_bench.indicators.velocity_points`), drawn small and translucent
        (paper Fig. 4). At most ``max_points`` are drawn (an evenly strided subset). ``None``
        draws no raw points.
    curve : VelocityGainCurve or sequence of VelocityGainCurve or None
        Smoothed curve(s): the local mean velocity of each occupied bin, drawn as a line
        against the bin centre. Several curves are overlaid (paper Fig. 8).
    indicators : IndicatorResult, mapping, sequence or None, default=None
        Indicators to annotate (paper Fig. 5), see :func:`annotate_indicators`. With several
        curves, a sequence aligned with them (``None`` entries skipped); overlaid curves get
        markers and lines in their colour but no text.
    labels : sequence of str, optional
        Legend labels of the curves (one per curve).
    max_points : int, default=50000
        Largest number of raw points drawn.
    show_fit : bool, default=True
        Draw the fitted piecewise-linear model of annotated curves.

    Returns
    -------
    matplotlib.axes.Axes
        ``ax``.

    Raises
    ------
    ParameterError
        Mismatched ``current``/``velocity``, ``labels`` or ``indicators`` lengths, or wrong
        types.
    """
    curves = _as_list(curve, VelocityGainCurve, "curve")
    if isinstance(indicators, (IndicatorResult, Mapping)):
        inds: list = [indicators]
    elif indicators is None:
        inds = []
    else:
        inds = list(indicators)
    if inds and len(inds) != max(len(curves), 1):
        raise ParameterError(
            f"The 'indicators' parameter of plot_velocity_gain must have one entry per curve "
            f"({len(curves)}). Got {len(inds)} instead."
        )
    if labels is not None and len(labels) != len(curves):
        raise ParameterError(
            f"The 'labels' parameter of plot_velocity_gain must have one label per curve "
            f"({len(curves)}). Got {len(labels)} instead."
        )
    if (current is None) != (velocity is None):
        raise ParameterError(
            "The 'current' and 'velocity' parameters of plot_velocity_gain must be both given "
            "or both None. Got only one of them instead."
        )
    if current is not None:
        i = np.asarray(current, dtype=np.float64).ravel()
        v = np.asarray(velocity, dtype=np.float64).ravel()
        if i.shape != v.shape:
            raise ParameterError(
                f"The 'velocity' parameter of plot_velocity_gain must have the shape of "
                f"'current' {i.shape}. Got {v.shape} instead."
            )
        step = max(1, int(math.ceil(len(i) / max(int(max_points), 1))))
        ax.scatter(i[::step], v[::step], s=2, alpha=0.2, color="tab:blue", linewidths=0,
                   rasterized=True, label="samples")
    multi = len(curves) > 1
    colors = [f"C{k % 10}" for k in range(len(curves))]
    if not multi and curves:
        colors = ["tab:red"]
    for k, crv in enumerate(curves):
        used = crv.count >= crv.config.min_bin_count
        label = labels[k] if labels is not None else "local mean"
        ax.plot(crv.bin_centres_ma[used], crv.mean_velocity_mm_s[used], "-", color=colors[k],
                lw=1.5, label=label)
    ax.set_xlabel(CURRENT_LABEL)
    ax.set_ylabel(VELOCITY_LABEL)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.axhline(0.0, color="0.5", lw=0.5)
    for k, ind in enumerate(inds):
        if ind is not None:
            color = colors[k] if multi else "k"
            annotate_indicators(ax, ind, color=color, show_fit=show_fit, text=not multi)
    if curves or current is not None:
        ax.legend(loc="upper left", fontsize=8, frameon=False)
    return ax


def velocity_gain_figure(current: np.ndarray | None, velocity: np.ndarray | None,
                         curve: VelocityGainCurve | Sequence[VelocityGainCurve] | None,
                         indicators: object = None, *, labels: Sequence[str] | None = None,
                         title: str | None = None, figsize: tuple[float, float] = (7.0, 4.5)
                         ) -> Figure:
    """A stand-alone figure (no pyplot; saved with the Agg backend) with one velocity-gain plot.

    Parameters
    ----------
    current, velocity, curve, indicators, labels
        As in :func:`plot_velocity_gain`.
    title : str, optional
        Axes title.
    figsize : tuple of float, default=(7.0, 4.5)
        Figure size, in inches.

    Returns
    -------
    matplotlib.figure.Figure
        Save it with ``fig.savefig(path)``.
    """
    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.add_subplot()
    plot_velocity_gain(ax, current, velocity, curve, indicators, labels=labels)
    if title:
        ax.set_title(title)
    return fig
