"""Calibration of guilt probabilities: Brier score and reliability diagram.

The paper reports probabilities of guilt; a method is *calibrated* when, among
the (flight, mode) pairs it gives guilt ``p``, a fraction ``p`` really are that
mode. The population is the alarmed single-fault flights (every flight where
a guilt distribution is a diagnosis and the true mode is one mode: the
population of the false classification rate).

* **Brier score** (Brier 1950, multi-class form): the mean over those flights
  of ``sum_m (g_m - y_m)^2`` with ``y`` the one-hot true mode; 0 is perfect, 2
  the worst (all guilt on a wrong mode), ``1 - 1/7 = 0.857`` for uniform guilt.
* **Reliability table**: the ``7 n`` (flight, mode) probabilities are binned
  into ``n_bins`` equal-width bins of ``[0, 1]``; per bin the mean predicted
  probability and the observed frequency of the mode being the true one. A
  calibrated method lies on the diagonal. The expected calibration error
  (ECE) is ``sum_b (count_b / total) |observed_b - predicted_b|``.

Worked value: two alarmed flights of true mode ``backlash``, one with all guilt
on ``backlash`` (contributes 0), one with all guilt on ``internal_leakage``
(contributes 1 + 1 = 2): Brier = 1.0.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.methods.tables import GUILT_COLUMNS
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["brier_score", "guilt_calibration", "plot_reliability", "reliability_table"]


def _population(flights: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    true_mode = flights["true_mode"].to_numpy()
    mask = np.isin(true_mode, MODE_IDS) & flights["alarm"].to_numpy(dtype=bool)
    guilt = flights.loc[mask, list(GUILT_COLUMNS)].to_numpy(dtype=float)
    onehot = (np.asarray(true_mode[mask])[:, None] == np.array(MODE_IDS)[None, :]).astype(float)
    return guilt, onehot


def brier_score(flights: pd.DataFrame) -> float:
    """Multi-class Brier score of the guilt of alarmed single-fault flights (NaN when none).

    Parameters
    ----------
    flights : pandas.DataFrame
        Per-flight table (:func:`fuelhm_bench.scoring.flight_table`).

    Returns
    -------
    float
        In [0, 2]; lower is better.

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> from fuelhm_bench.methods import GUILT_COLUMNS
    >>> g = np.zeros((2, 7)); g[0, 2] = 1.0; g[1, 5] = 1.0   # backlash, internal_leakage
    >>> f = pd.DataFrame(g, columns=GUILT_COLUMNS).assign(true_mode="backlash", alarm=True)
    >>> brier_score(f)
    1.0
    """
    guilt, onehot = _population(flights)
    if len(guilt) == 0:
        return float("nan")
    return float(((guilt - onehot) ** 2).sum(axis=1).mean())


def reliability_table(flights: pd.DataFrame, *, n_bins: int = 10) -> pd.DataFrame:
    """Reliability diagram data of the guilt probabilities.

    Parameters
    ----------
    flights : pandas.DataFrame
        Per-flight table.
    n_bins : int, default=10
        Equal-width bins of [0, 1] (the last one closed).

    Returns
    -------
    pandas.DataFrame
        ``bin_low, bin_high, count, mean_predicted, observed_frequency`` (NaN
        for empty bins).
    """
    if isinstance(n_bins, bool) or not isinstance(n_bins, (int, np.integer)) or n_bins < 1:
        raise ParameterError(f"The 'n_bins' parameter of reliability_table must be an int >= 1. "
                             f"Got {n_bins!r} instead.")
    guilt, onehot = _population(flights)
    p, y = guilt.ravel(), onehot.ravel()
    edges = np.linspace(0.0, 1.0, n_bins + 1)
    idx = np.clip(np.searchsorted(edges, p, side="right") - 1, 0, n_bins - 1)
    count = np.bincount(idx, minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_p = np.bincount(idx, weights=p, minlength=n_bins) / count
        freq = np.bincount(idx, weights=y, minlength=n_bins) / count
    return pd.DataFrame({"bin_low": edges[:-1], "bin_high": edges[1:], "count": count,
                         "mean_predicted": np.where(count > 0, mean_p, np.nan),
                         "observed_frequency": np.where(count > 0, freq, np.nan)})


def guilt_calibration(flights: pd.DataFrame, *, n_bins: int = 10) -> dict:
    """Brier score, expected calibration error and reliability table of one run.

    Returns
    -------
    dict
        ``brier``, ``ece``, ``n_flights`` (alarmed single-fault flights) and
        ``reliability`` (:func:`reliability_table`).
    """
    table = reliability_table(flights, n_bins=n_bins)
    total = table["count"].sum()
    gap = (table["observed_frequency"] - table["mean_predicted"]).abs().fillna(0.0)
    ece = float((table["count"] * gap).sum() / total) if total else float("nan")
    return {"brier": brier_score(flights), "ece": ece, "n_flights": int(total // len(MODE_IDS)),
            "reliability": table}


def plot_reliability(tables: dict[str, pd.DataFrame], path=None):
    """Reliability diagram of several methods (one line each) on one axes.

    Parameters
    ----------
    tables : dict of str to pandas.DataFrame
        Method name -> :func:`reliability_table`.
    path : str or path-like, optional
        Where to save the figure (PNG or SVG by extension).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from fuelhm_bench.scoring.figures import apply_tight_layout

    fig = Figure(figsize=(4.5, 4.5))  # the object API: no pyplot state, no display
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot([0, 1], [0, 1], color="grey", linestyle="--", label="calibrated")
    for name, t in tables.items():
        ok = t["count"] > 0
        ax.plot(t.loc[ok, "mean_predicted"], t.loc[ok, "observed_frequency"], marker="o",
                label=name)
    ax.set_xlabel("guilt probability (mean in bin)")
    ax.set_ylabel("observed frequency of the true mode")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(fontsize="small")
    apply_tight_layout(fig)
    if path is not None:
        fig.savefig(path)
    return fig
