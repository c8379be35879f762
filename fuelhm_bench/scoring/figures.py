"""Figure of the global-score distributions with thresholds (paper Fig. 10).

Uses matplotlib's object API with the Agg canvas: no pyplot state, no display.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from scipy.stats import norm

from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.scoring.detection import modes_present
from fuelhm_bench.scoring.run import HEALTHY, Run, flight_table
from fuelhm_bench.scoring.thresholds import fit_healthy_model

__all__ = ["apply_tight_layout", "plot_score_distributions", "save_figure"]


def plot_score_distributions(run: Run, config: ScoringConfig | None = None, *, bins: int = 40,
                             detectable_only: bool = True) -> Figure:
    """Histograms of the global score, healthy vs each mode, with Gaussian fits and thresholds.

    Parameters
    ----------
    run : Run
    config : ScoringConfig or None, default=None
        ``a_values`` gives the threshold lines.
    bins : int, default=40
        Number of histogram bins over the common score range.
    detectable_only : bool, default=True
        Plot only detectable faulty flights of each mode (else every faulty
        flight of the mode).

    Returns
    -------
    matplotlib.figure.Figure
        One axes: density histograms (healthy training, healthy evaluation,
        one per mode), the maximum-likelihood Gaussian of each (solid lines), and
        dashed vertical lines at ``Thr = mu + A sigma``.
    """
    config = ScoringConfig() if config is None else config
    flights = flight_table(run, config)
    model = fit_healthy_model(run.healthy_scores)
    groups = [("healthy (training)", np.asarray(run.healthy_scores)),
              ("healthy (evaluation)",
               flights.loc[flights["true_mode"] == HEALTHY, "score"].to_numpy(float))]
    for mode in modes_present(flights):
        sel = flights["true_mode"] == mode
        if detectable_only:
            sel &= flights["detectable"]
        groups.append((mode, flights.loc[sel, "score"].to_numpy(float)))
    groups = [(n, s) for n, s in groups if s.size]
    values = np.concatenate([s for _, s in groups])
    thresholds = [model.threshold(a) for a in config.a_values]
    lo = min(values.min(), *thresholds)
    hi = max(values.max(), *thresholds)
    if hi <= lo:
        hi = lo + 1.0
    edges = np.linspace(lo, hi, bins + 1)
    grid = np.linspace(lo, hi, 400)

    fig = Figure(figsize=(8, 4.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    colors = [f"C{i}" for i in range(10)]
    for i, (name, s) in enumerate(groups):
        color = colors[i % len(colors)]
        # one filled outline per group (hist draws a patch per bin: ~10x the drawing time)
        density, _ = np.histogram(s, bins=edges, density=True)
        ax.stairs(density, edges, fill=True, alpha=0.35 if i == 0 else 0.25, color=color,
                  label=f"{name} (n={s.size})")
        sd = s.std(ddof=0)
        if s.size >= 2 and sd > 0:
            ax.plot(grid, norm.pdf(grid, s.mean(), sd), color=color, lw=1.5)
    ymax = ax.get_ylim()[1]
    for a, thr in zip(config.a_values, thresholds):
        ax.axvline(thr, color="k", ls="--", lw=0.8)
        ax.text(thr, ymax * 0.95, f" A={a:g}", rotation=90, va="top", ha="left", fontsize=7)
    ax.set_xlabel("global score (method units)")
    ax.set_ylabel("density")
    ax.set_title(f"{run.name}\nglobal-score distributions, Thr = mu + A sigma "
                 f"(mu={model.mu:.3g}, sigma={model.sigma:.3g})", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    apply_tight_layout(fig)
    return fig


def apply_tight_layout(fig: Figure) -> None:
    """``fig.tight_layout()``, applied once, leaving the figure without a layout engine.

    After ``Figure.tight_layout`` matplotlib keeps a placeholder layout engine, and ``savefig``
    then draws the whole figure once more before drawing it into the file: about a third of
    the time a report figure takes to save. The layout is fixed once applied, so the
    placeholder is dropped (the rc settings that would pick another engine are held off).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    """
    fig.tight_layout()
    with matplotlib.rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
        fig.set_layout_engine(None)


def save_figure(fig: Figure, path: str | Path, *, dpi: int = 120, close: bool = False) -> Path:
    """Save a figure (format from the extension, e.g. .png, .pdf, .svg); returns the path.

    With ``close=True`` the figure is also closed (released by pyplot): batch writers that draw one
    figure per entry pass it, so a long run does not keep every figure in memory.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    if close:
        import matplotlib.pyplot as plt

        plt.close(fig)
    return path
