"""The leaderboard page: one static, self-contained ``index.html`` built from a results table.

No CDN, no external resource: the styles and the sorting script are inline,
the critical-difference diagram is inline SVG, so the page works offline and
from ``file://``. Every table sorts by clicking a header (numbers numerically,
text alphabetically; a second click reverses). A view of the results: it reads
a DataFrame (today the rows of ``leaderboard.csv``; later the results store)
and writes nothing else.

Expected columns of the results table (extra columns are shown too):
``method``, ``scenario``, ``status`` and, for ``ok`` rows, the KPIs; optional
``seed``, ``params`` (text), ``message`` (failed rows), ``<kpi>_ci_low`` /
``<kpi>_ci_high`` (shown as ``value [low, high]``), ``links`` (a mapping
label -> path relative to the page; only paths that exist are linked).
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path
from typing import Any, Mapping

import pandas as pd

__all__ = ["leaderboard_html", "write_leaderboard_page"]

#: KPI columns shown first, in this order, when present (lower is better unless listed in _HIGHER).
_KPI_ORDER = ("summary_score", "balanced_accuracy_alarm", "fpr_standard_alarm", "fnr_standard_alarm",
              "fpr_standard_thr", "fnr_standard_thr", "fcr", "brier", "ece",
              "detected_event_fraction", "delay_censored_mean", "cost_kusd", "robustness")

_STYLE = """
body{font-family:sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em 0;font-size:13px}
th,td{border:1px solid #ccc;padding:3px 6px;text-align:right}
th{background:#eee;cursor:pointer;user-select:none}
th.asc::after{content:" \\25B2"} th.desc::after{content:" \\25BC"}
td.text{text-align:left} tr.failed td{background:#fdecea}
.ci{color:#666;font-size:11px} .msg{color:#a00;text-align:left;max-width:40em}
"""

_SCRIPT = """
function cellKey(td){var v=td.getAttribute('data-sort');if(v===null)v=td.textContent;
 var n=parseFloat(v);return (v.trim()!==''&&!isNaN(n)&&isFinite(v))?{n:true,v:n}:{n:false,v:v.trim().toLowerCase()};}
function sortTable(th){var table=th.closest('table');var idx=Array.prototype.indexOf.call(th.parentNode.children,th);
 var asc=!th.classList.contains('asc');
 Array.prototype.forEach.call(th.parentNode.children,function(h){h.classList.remove('asc','desc');});
 th.classList.add(asc?'asc':'desc');var body=table.tBodies[0];var rows=Array.prototype.slice.call(body.rows);
 rows.sort(function(a,b){var x=cellKey(a.cells[idx]),y=cellKey(b.cells[idx]);
  if(x.v===''&&y.v!=='')return 1;if(y.v===''&&x.v!=='')return -1;
  var c;if(x.n&&y.n)c=x.v-y.v;else if(x.n)c=-1;else if(y.n)c=1;else c=x.v<y.v?-1:(x.v>y.v?1:0);
  return asc?c:-c;});
 rows.forEach(function(r){body.appendChild(r);});}
document.addEventListener('DOMContentLoaded',function(){
 document.querySelectorAll('table.sortable th').forEach(function(th){
  th.addEventListener('click',function(){sortTable(th);});});});
"""


def _fmt(value: Any) -> tuple[str, str, bool]:
    """(display text, sort key, numeric) of a cell."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "", "", True
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return f"{value:.4g}", repr(float(value)), True
    return str(value), str(value), False


def _table(frame: pd.DataFrame, table_id: str, out_dir: Path | None) -> str:
    kpis = [c for c in frame.columns if not c.endswith(("_ci_low", "_ci_high"))
            and c not in ("links", "message")]
    head = "".join(f"<th>{html.escape(c)}</th>" for c in kpis)
    has_msg = "message" in frame.columns
    has_links = "links" in frame.columns
    head += "<th>message</th>" if has_msg else ""
    head += "<th>files</th>" if has_links else ""
    rows = []
    for _, row in frame.iterrows():
        status = str(row.get("status", "ok"))
        cells = []
        for c in kpis:
            text, key, numeric = _fmt(row[c])
            cls = "" if numeric else ' class="text"'
            ci = ""
            low, high = row.get(f"{c}_ci_low"), row.get(f"{c}_ci_high")
            if low is not None and high is not None and not (pd.isna(low) or pd.isna(high)):
                ci = f' <span class="ci">[{low:.4g}, {high:.4g}]</span>'
            cells.append(f'<td{cls} data-sort="{html.escape(key)}">{html.escape(text)}{ci}</td>')
        if has_msg:
            msg = row.get("message")
            msg = "" if msg is None or (isinstance(msg, float) and math.isnan(msg)) else str(msg)
            first = msg.strip().splitlines()[0] if msg.strip() else ""
            cells.append(f'<td class="msg" data-sort="{html.escape(first)}">{html.escape(first)}</td>')
        if has_links:
            links = row.get("links")
            links = links if isinstance(links, Mapping) else {}
            anchors = [f'<a href="{html.escape(Path(p).as_posix())}">{html.escape(label)}</a>'
                       for label, p in links.items()
                       if out_dir is None or (out_dir / p).exists()]
            cells.append(f'<td class="text" data-sort="">{" ".join(anchors)}</td>')
        cls = ' class="failed"' if status != "ok" else ""
        rows.append(f"<tr{cls}>{''.join(cells)}</tr>")
    return (f'<table class="sortable" id="{html.escape(table_id)}"><thead><tr>{head}</tr></thead>'
            f"<tbody>{''.join(rows)}</tbody></table>")


def leaderboard_html(results: pd.DataFrame, *, value: str = "summary_score",
                     title: str = "fuelhm-bench leaderboard", out_dir: Path | None = None,
                     alpha: float = 0.05) -> str:
    """The page as a string (see the module docstring for the columns of ``results``).

    Parameters
    ----------
    results : pandas.DataFrame
        One row per (method, scenario[, seed]) entry.
    value : str, default="summary_score"
        KPI that ranks the methods (higher is better).
    title : str, default="fuelhm-bench leaderboard"
    out_dir : pathlib.Path or None, default=None
        Directory the page will live in: links to missing files are dropped.
    alpha : float, default=0.05
        Level of the Friedman test and of the critical difference.

    Returns
    -------
    str
        A complete HTML document.
    """
    from fuelhm_bench.scoring.ranking import aggregate_ranking, cd_diagram

    frame = results.copy()
    if "status" not in frame.columns:
        frame["status"] = "ok"
    first = [c for c in ("scenario", "seed", "method", "params", "status") if c in frame.columns]
    kpis = [c for c in _KPI_ORDER if c in frame.columns]
    rest = [c for c in frame.columns if c not in first + kpis and c not in ("links", "message")
            and not c.endswith(("_ci_low", "_ci_high")) and c != "fidelity"]
    ci = [c for c in frame.columns if c.endswith(("_ci_low", "_ci_high"))]
    extra = [c for c in ("message", "links") if c in frame.columns]
    body = [f"<h1>{html.escape(title)}</h1>",
            f"<p>Ranked by <b>{html.escape(value)}</b> (null method = 0, perfect = 100). Brackets: "
            f"95 % confidence intervals resampling units. Click a column header to sort.</p>"]

    body.append("<h2>Aggregate over scenarios and seeds</h2>")
    agg = aggregate_ranking(frame, value=value, alpha=alpha) \
        if value in frame.columns and "method" in frame.columns else None
    if agg is not None and len(agg.table) >= 2:  # the one aggregate of every view (scoring.ranking)
        ranks, fr, cd = agg.table, agg.friedman, agg.critical_difference
        k, n = len(ranks), fr["n_blocks"]
        body.append(_table(ranks[["method", "mean_rank", "n_blocks", f"mean_{value}"]], "aggregate", out_dir))
        if n >= 1 and k >= 2:
            if fr["pvalue"] == fr["pvalue"]:
                body.append(f"<p>Friedman test over {n} blocks and {k} methods: chi2 = "
                            f"{fr['statistic']:.3g}, p = {fr['pvalue']:.3g}. Nemenyi critical "
                            f"difference at alpha = {alpha:g}: {cd:.3g} (methods joined by a bar "
                            f"do not differ significantly).</p>")
            else:
                body.append(f"<p>{html.escape(fr['note'])}. Nemenyi critical difference: "
                            f"{cd:.3g}.</p>")
            body.append(f'<div id="cd-diagram">{cd_diagram(ranks, cd, title=f"mean rank by {value}")}</div>')
    else:
        body.append("<p>Fewer than two methods with results: no ranking.</p>")

    cols = first + kpis + rest + ci + extra
    for scenario, part in frame.groupby("scenario", sort=True) if "scenario" in frame.columns \
            else [("all", frame)]:
        part = part.sort_values(value, ascending=False, na_position="last") \
            if value in part.columns else part
        body.append(f"<h2>Scenario {html.escape(str(scenario))}</h2>")
        body.append(_table(part[cols].drop(columns=["scenario"], errors="ignore"),
                           f"scenario-{scenario}", out_dir))
    failed = frame[frame["status"] != "ok"]
    if len(failed):
        body.append(f"<h2>Failed entries ({len(failed)})</h2>")
        body.append(_table(failed[[c for c in first + extra if c in failed.columns]], "failed",
                           out_dir))
    return ("<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{_STYLE}</style>"
            f"<script>{_SCRIPT}</script></head><body>{''.join(body)}</body></html>")


def write_leaderboard_page(results: pd.DataFrame, out_dir, **kwargs) -> Path:
    """Write ``<out_dir>/index.html`` (:func:`leaderboard_html`); returns its path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "index.html"
    path.write_text(leaderboard_html(results, out_dir=out, **kwargs), encoding="utf-8")
    return path


def _params_text(params: Mapping | None) -> str:
    """Hyperparameters as a short, stable text (sorted keys)."""
    return json.dumps(dict(params or {}), sort_keys=True, default=str) if params else ""
