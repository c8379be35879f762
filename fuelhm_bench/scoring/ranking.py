"""Aggregate over scenarios and seeds: mean ranks, the Friedman test, critical differences.

The protocol of Demšar (2006), "Statistical comparisons of classifiers over
multiple data sets", JMLR 7: a *block* is one (scenario, seed) evaluation; the
methods are ranked inside each block (1 = best, ties share the mean rank); the
Friedman test asks whether the mean ranks differ more than chance; the
Nemenyi post-hoc test calls two methods different when their mean ranks differ
by more than the critical difference::

    CD = q_alpha * sqrt(k (k + 1) / (6 N))

with ``k`` methods, ``N`` blocks and ``q_alpha`` the studentized-range quantile
divided by sqrt(2) (``scipy.stats.studentized_range``). Worked value: ``k = 4``
methods on ``N = 14`` blocks at ``alpha = 0.05``: ``q = 2.569``,
``CD = 2.569 * sqrt(20 / 84) = 1.254``. The Wilcoxon signed-rank test with
Holm's correction (Benavoli et al. 2016) is offered as the alternative
post-hoc test.

Only blocks where every method has a finite value enter the tests (a failed
entry has no KPI); :func:`mean_ranks` reports how many blocks were used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations
from typing import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from fuelhm_bench.errors import DataFormatError, ParameterError

__all__ = ["Aggregate", "aggregate_ranking", "critical_difference", "friedman_test", "mean_ranks",
           "rank_matrix", "wilcoxon_holm", "cd_diagram"]

_BLOCKS = ("scenario", "seed")


def rank_matrix(results: pd.DataFrame, *, value: str = "summary_score",
                method: str = "method", blocks: Sequence[str] = _BLOCKS,
                higher_is_better: bool = True) -> pd.DataFrame:
    """Ranks of the methods in every complete block.

    Parameters
    ----------
    results : pandas.DataFrame
        One row per (method, block): columns ``method``, the ``blocks``
        columns and ``value``. Missing block columns are treated as constant
        (e.g. no ``seed`` column: one seed).
    value : str, default="summary_score"
        KPI column.
    method : str, default="method"
        Method column (a method's name plus its parameters: one ranked entry).
    blocks : sequence of str, default=("scenario", "seed")
        Columns identifying a block.
    higher_is_better : bool, default=True

    Returns
    -------
    pandas.DataFrame
        Index: blocks (complete ones only: every method has a finite value);
        columns: methods (in order of first appearance); values: rank (1 = best).

    Raises
    ------
    DataFormatError
        When a column is missing or a (method, block) pair appears twice.
    """
    missing = [c for c in (method, value) if c not in results.columns]
    if missing:
        raise DataFormatError(f"The 'results' parameter of rank_matrix must have the columns "
                              f"{[method, value]} (and optionally {list(blocks)}). Missing "
                              f"{missing}.")
    frame = results.copy()
    keys = []
    for b in blocks:
        if b not in frame.columns:
            continue
        frame[b] = frame[b].astype(object).where(frame[b].notna(), "default")
        keys.append(b)
    if not keys:
        frame["_block"] = "all"
        keys = ["_block"]
    if frame.duplicated([*keys, method]).any():
        row = frame.loc[frame.duplicated([*keys, method]), [*keys, method]].iloc[0]
        raise DataFormatError(f"The 'results' parameter of rank_matrix must have one row per "
                              f"method and block. Got {dict(row)} twice instead.")
    order = list(pd.unique(frame[method]))
    wide = frame.pivot(index=keys, columns=method, values=value).reindex(columns=order)
    wide = wide.apply(pd.to_numeric, errors="coerce")
    complete = wide[np.isfinite(wide.to_numpy(dtype=float)).all(axis=1)]
    values = complete.to_numpy(dtype=float)
    ranks = np.array([stats.rankdata(-v if higher_is_better else v) for v in values]) \
        if len(values) else np.empty((0, len(order)))
    return pd.DataFrame(ranks, index=complete.index, columns=order)


def mean_ranks(results: pd.DataFrame, **kwargs) -> pd.DataFrame:
    """Mean rank per method over the complete blocks (keywords of :func:`rank_matrix`).

    Returns
    -------
    pandas.DataFrame
        ``method, mean_rank, n_blocks``, best first.

    Examples
    --------
    >>> import pandas as pd
    >>> r = pd.DataFrame({"method": ["a", "b", "a", "b"], "scenario": ["s1", "s1", "s2", "s2"],
    ...                   "summary_score": [10.0, 5.0, 3.0, 7.0]})
    >>> mean_ranks(r)[["method", "mean_rank"]].values.tolist()
    [['a', 1.5], ['b', 1.5]]
    """
    ranks = rank_matrix(results, **kwargs)
    out = pd.DataFrame({"method": list(ranks.columns),
                        "mean_rank": ranks.mean(axis=0).to_numpy(dtype=float),
                        "n_blocks": len(ranks)})
    return out.sort_values("mean_rank", kind="stable").reset_index(drop=True)


def friedman_test(results: pd.DataFrame, **kwargs) -> dict:
    """Friedman's test that all methods have the same mean rank (``scipy.stats.friedmanchisquare``).

    Parameters
    ----------
    results : pandas.DataFrame
        As for :func:`rank_matrix` (same keywords).

    Returns
    -------
    dict
        ``statistic`` (chi-square), ``pvalue``, ``n_methods``, ``n_blocks``;
        statistic and p-value are NaN with fewer than 3 methods or 2 complete
        blocks (the test is then undefined), with the reason in ``note``.
    """
    ranks = rank_matrix(results, **kwargs)
    k, n = ranks.shape[1], ranks.shape[0]
    out = {"statistic": math.nan, "pvalue": math.nan, "n_methods": k, "n_blocks": n, "note": ""}
    if k < 3 or n < 2:
        out["note"] = (f"Friedman test needs at least 3 methods and 2 complete blocks; got {k} "
                       f"methods and {n} blocks")
        return out
    res = stats.friedmanchisquare(*[ranks[c].to_numpy() for c in ranks.columns])
    out["statistic"], out["pvalue"] = float(res.statistic), float(res.pvalue)
    return out


def critical_difference(n_methods: int, n_blocks: int, alpha: float = 0.05) -> float:
    """Nemenyi critical difference of mean ranks (Demšar 2006, eq. in section 3.2.2).

    Parameters
    ----------
    n_methods : int
        ``k`` >= 2.
    n_blocks : int
        ``N`` >= 1.
    alpha : float, default=0.05

    Returns
    -------
    float

    Examples
    --------
    >>> round(critical_difference(4, 14), 3)
    1.254
    """
    if not (isinstance(n_methods, (int, np.integer)) and n_methods >= 2):
        raise ParameterError(f"The 'n_methods' parameter of critical_difference must be an int "
                             f">= 2. Got {n_methods!r} instead.")
    if not (isinstance(n_blocks, (int, np.integer)) and n_blocks >= 1):
        raise ParameterError(f"The 'n_blocks' parameter of critical_difference must be an int "
                             f">= 1. Got {n_blocks!r} instead.")
    if not 0 < alpha < 1:
        raise ParameterError(f"The 'alpha' parameter of critical_difference must be a float in "
                             f"(0, 1). Got {alpha!r} instead.")
    q = stats.studentized_range.ppf(1 - alpha, n_methods, np.inf) / math.sqrt(2)
    return float(q * math.sqrt(n_methods * (n_methods + 1) / (6.0 * n_blocks)))


def wilcoxon_holm(results: pd.DataFrame, *, alpha: float = 0.05, **kwargs) -> pd.DataFrame:
    """Pairwise Wilcoxon signed-rank tests on the KPI values, Holm-corrected.

    Parameters
    ----------
    results : pandas.DataFrame
        As for :func:`rank_matrix` (same keywords).
    alpha : float, default=0.05
        Family-wise error rate.

    Returns
    -------
    pandas.DataFrame
        ``method_a, method_b, pvalue, pvalue_holm, significant`` per pair
        (``scipy.stats.wilcoxon``; a pair with identical values has p = 1).
    """
    value = kwargs.pop("value", "summary_score")
    method = kwargs.get("method", "method")
    ranks = rank_matrix(results, value=value, **kwargs)
    keys = list(ranks.index.names)
    frame = results.copy()
    for b in keys:
        if b in frame.columns:
            frame[b] = frame[b].astype(object).where(frame[b].notna(), "default")
    if keys == ["_block"]:
        frame["_block"] = "all"
    wide = frame.pivot(index=keys, columns=method, values=value).loc[ranks.index, ranks.columns]
    rows = []
    for a, b in combinations(ranks.columns, 2):
        d = wide[a].to_numpy(float) - wide[b].to_numpy(float)
        p = 1.0 if np.all(d == 0) else float(stats.wilcoxon(wide[a], wide[b]).pvalue)
        rows.append({"method_a": a, "method_b": b, "pvalue": p})
    out = pd.DataFrame(rows, columns=["method_a", "method_b", "pvalue"])
    m = len(out)
    order = np.argsort(out["pvalue"].to_numpy(), kind="stable")
    holm = np.empty(m)
    running = 0.0
    for i, j in enumerate(order):
        running = max(running, min(1.0, (m - i) * out["pvalue"].iloc[j]))
        holm[j] = running
    out["pvalue_holm"] = holm
    out["significant"] = out["pvalue_holm"] < alpha
    return out


def _cliques(ranks: pd.Series, cd: float) -> list[tuple[int, int]]:
    """Maximal runs (start, end positions in sorted order) whose rank spread is below cd."""
    r = ranks.to_numpy(float)
    spans = []
    for i in range(len(r)):
        j = i
        while j + 1 < len(r) and r[j + 1] - r[i] < cd:
            j += 1
        if j > i and not any(s <= i and j <= e for s, e in spans):
            spans.append((i, j))
    return spans


def cd_diagram(ranks: pd.DataFrame, cd: float, *, title: str = "") -> str:
    """A critical-difference diagram as a self-contained SVG string.

    Parameters
    ----------
    ranks : pandas.DataFrame
        Output of :func:`mean_ranks` (``method``, ``mean_rank``).
    cd : float
        Critical difference (:func:`critical_difference`); methods joined by a
        bar are not significantly different.
    title : str, default=""

    Returns
    -------
    str
        ``<svg ...>...</svg>`` (no external resource), axis from rank 1 to ``k``.
    """
    from xml.sax.saxutils import escape

    r = ranks.sort_values("mean_rank", kind="stable").reset_index(drop=True)
    k = max(2, len(r))
    width, left, right = 720, 230, 490
    n_left = (len(r) + 1) // 2
    height = 110 + 22 * max(n_left, len(r) - n_left)

    def x(rank: float) -> float:
        return left + (rank - 1) / (k - 1) * (right - left)

    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="12">',
             f'<title>{escape(title or "Critical-difference diagram")}</title>',
             f'<text x="{left}" y="16">{escape(title)}</text>',
             f'<line x1="{left}" y1="50" x2="{right}" y2="50" stroke="black"/>']
    for t in range(1, k + 1):
        parts.append(f'<line x1="{x(t):.1f}" y1="45" x2="{x(t):.1f}" y2="55" stroke="black"/>'
                     f'<text x="{x(t):.1f}" y="40" text-anchor="middle">{t}</text>')
    if math.isfinite(cd):
        parts.append(f'<line x1="{x(1):.1f}" y1="26" x2="{x(min(k, 1 + cd)):.1f}" y2="26" '
                     f'stroke="black" stroke-width="2"/><text x="{x(1):.1f}" y="22">'
                     f'CD = {cd:.2f}</text>')
    for i, row in r.iterrows():
        px = x(float(row["mean_rank"]))
        on_left = i < n_left
        y = 80 + 22 * (i if on_left else len(r) - 1 - i)
        tx = left - 10 if on_left else right + 10
        parts.append(f'<polyline points="{px:.1f},50 {px:.1f},{y} {tx:.1f},{y}" fill="none" '
                     f'stroke="black"/>')
        anchor = "end" if on_left else "start"
        label = escape(f"{row['method']} ({row['mean_rank']:.2f})")
        parts.append(f'<text class="cd-method" x="{(tx - 3) if on_left else (tx + 3):.1f}" '
                     f'y="{y - 3}" text-anchor="{anchor}">{label}</text>')
    if math.isfinite(cd):
        for n, (s, e) in enumerate(_cliques(r["mean_rank"], cd)):
            y = 58 + 5 * n
            parts.append(f'<line class="cd-clique" x1="{x(r["mean_rank"][s]) - 3:.1f}" y1="{y}" '
                         f'x2="{x(r["mean_rank"][e]) + 3:.1f}" y2="{y}" stroke="black" '
                         f'stroke-width="3"/>')
    parts.append("</svg>")
    return "".join(parts)


@dataclass(frozen=True, eq=False)
class Aggregate:
    """The aggregate of a leaderboard over its blocks (see :func:`aggregate_ranking`).

    Attributes
    ----------
    table : pandas.DataFrame
        One row per entry, best mean rank first: ``method``, ``mean_rank``,
        ``n_blocks``, ``mean_<value>`` (over the complete blocks),
        ``rank_gap_to_best``, ``nemenyi_differs_from_best`` (gap > CD) and
        ``wilcoxon_holm_p_vs_best`` (Holm-corrected p of the pair with the best
        entry; NaN for the best itself or with fewer than 2 blocks).
    friedman : dict
        :func:`friedman_test` (``statistic``, ``pvalue``, ``n_methods``, ``n_blocks``, ``note``).
    critical_difference : float
        Nemenyi CD at ``alpha`` (NaN with fewer than 2 entries or no complete block).
    pairs : pandas.DataFrame
        :func:`wilcoxon_holm` over all pairs (empty with fewer than 2 blocks).
    alpha : float
    value : str
        The ranked KPI.
    """

    table: pd.DataFrame
    friedman: dict
    critical_difference: float
    pairs: pd.DataFrame
    alpha: float
    value: str

    def summary(self) -> str:
        """One paragraph stating the test results with their numbers (for Markdown views)."""
        fr, k, n = self.friedman, self.friedman["n_methods"], self.friedman["n_blocks"]
        if fr["pvalue"] == fr["pvalue"]:
            text = (f"Friedman test over {n} blocks (scenario x seed) and {k} entries: chi2 = "
                    f"{fr['statistic']:.3g}, p = {fr['pvalue']:.3g}.")
        else:
            text = f"{fr['note']}."
        if math.isfinite(self.critical_difference):
            n_diff = int(self.table["nemenyi_differs_from_best"].sum())
            text += (f" Nemenyi critical difference at alpha = {self.alpha:g}: {self.critical_difference:.3g} "
                     f"mean ranks; {n_diff} of {k - 1} entries differ significantly from the best.")
        if len(self.pairs):
            text += (f" Wilcoxon signed-rank with Holm's correction: {int(self.pairs['significant'].sum())} of "
                     f"{len(self.pairs)} pairs differ at alpha = {self.alpha:g}.")
        return text


def aggregate_ranking(results: pd.DataFrame, *, value: str = "summary_score", alpha: float = 0.05,
                      blocks: Sequence[str] = _BLOCKS) -> Aggregate:
    """Mean ranks, Friedman test, Nemenyi CD and Wilcoxon-Holm of a leaderboard (the one home of its aggregate).

    Parameters
    ----------
    results : pandas.DataFrame
        Leaderboard rows: ``method``, optionally ``params`` (an entry is a
        method with its parameters: ``"<method> <params>"`` when a method
        appears with several), ``status`` (only ``"ok"`` rows enter), the
        ``blocks`` columns and ``value``.
    value : str, default="summary_score"
        KPI to rank (higher is better).
    alpha : float, default=0.05
    blocks : sequence of str, default=("scenario", "seed")

    Returns
    -------
    Aggregate

    Examples
    --------
    >>> import pandas as pd
    >>> r = pd.DataFrame({"method": list("abc") * 4, "scenario": [s for s in "wxyz" for _ in range(3)],
    ...                   "summary_score": [9, 5, 1, 8, 6, 2, 9, 4, 3, 7, 6, 1.0]})
    >>> agg = aggregate_ranking(r)
    >>> agg.table[["method", "mean_rank"]].values.tolist()
    [['a', 1.0], ['b', 2.0], ['c', 3.0]]
    >>> round(agg.friedman["pvalue"], 4), round(agg.critical_difference, 3)
    (0.0183, 1.657)
    """
    frame = results
    if "status" in frame.columns:
        frame = frame[frame["status"] == "ok"]
    if value not in frame.columns:
        raise DataFormatError(f"The 'results' parameter of aggregate_ranking must have a {value!r} column. "
                              f"Got columns {list(results.columns)} instead.")
    frame = frame[pd.to_numeric(frame[value], errors="coerce").notna()].copy()
    if "params" in frame.columns:
        several = frame.groupby("method")["params"].transform("nunique") > 1
        frame["method"] = np.where(several, frame["method"] + " " + frame["params"].fillna("").astype(str),
                                   frame["method"])
    keys = {"value": value, "blocks": blocks}
    empty_pairs = pd.DataFrame(columns=["method_a", "method_b", "pvalue", "pvalue_holm", "significant"])
    if frame["method"].nunique() < 2:
        table = pd.DataFrame(columns=["method", "mean_rank", "n_blocks", f"mean_{value}", "rank_gap_to_best",
                                      "nemenyi_differs_from_best", "wilcoxon_holm_p_vs_best"])
        note = "fewer than two entries with results: no ranking"
        return Aggregate(table, {"statistic": math.nan, "pvalue": math.nan, "n_methods": frame["method"].nunique(),
                                 "n_blocks": 0, "note": note}, math.nan, empty_pairs, alpha, value)
    ranks = rank_matrix(frame, **keys)
    table = mean_ranks(frame, **keys)
    fr = friedman_test(frame, **keys)
    k, n = len(table), len(ranks)
    cd = critical_difference(k, n, alpha) if n >= 1 else math.nan
    complete = ranks.index
    key_cols = list(complete.names)
    if key_cols != ["_block"]:
        sub = frame.set_index(key_cols)
        sub = sub[sub.index.isin(complete)]
        means = sub.groupby("method")[value].apply(lambda v: float(pd.to_numeric(v).mean()))
    else:
        means = frame.groupby("method")[value].apply(lambda v: float(pd.to_numeric(v).mean()))
    table[f"mean_{value}"] = table["method"].map(means)
    best = table["method"].iloc[0]
    table["rank_gap_to_best"] = table["mean_rank"] - table["mean_rank"].iloc[0]
    table["nemenyi_differs_from_best"] = table["rank_gap_to_best"] > cd if math.isfinite(cd) else False
    pairs = wilcoxon_holm(frame, alpha=alpha, **keys) if n >= 2 else empty_pairs
    p_best = {}
    for r in pairs.itertuples():
        if best in (r.method_a, r.method_b):
            p_best[r.method_b if r.method_a == best else r.method_a] = r.pvalue_holm
    table["wilcoxon_holm_p_vs_best"] = table["method"].map(p_best).astype(float)
    return Aggregate(table, fr, cd, pairs, alpha, value)
