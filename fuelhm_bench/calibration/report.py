"""Plots (matplotlib, Agg) and the Markdown report of the recalibration and discrepancy workflows."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from fuelhm_bench.calibration.curve import DIRECTION_NAMES, CurveConfig, cell_residuals, pooled_curve
from fuelhm_bench.calibration.recalibrate import RECALIBRATION_PARAMETERS
from fuelhm_bench.errors import OutputPathError


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: str | Path) -> Path:
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=110, bbox_inches="tight")
    except OSError as exc:
        raise OutputPathError(f"Cannot write the figure {path}: {exc.strerror or exc}.") from None
    finally:
        _pyplot().close(fig)
    return path


def plot_curves(rs, curves: dict, path: str | Path, *, curve: CurveConfig = CurveConfig(), title: str = "",
                max_points: int = 20000, seed: int = 0) -> Path:
    """Measured points, measured local-mean curve and model curves over them (the paper's Fig. 7).

    Parameters
    ----------
    rs : ReplaySet
        Samples (the scored ones are drawn).
    curves : dict
        Label -> replayed model velocity on ``rs`` [mm/s]; each is drawn as its local-mean
        curve over the same samples, and its residual curve in a lower panel.
    path : str or Path
        Output image (PNG).
    curve : CurveConfig
        Bins of the local means.
    title : str
        Figure title.
    max_points : int, default=20000
        Largest number of measured points drawn (seeded subsample).
    seed : int, default=0
        Seed of the subsample.

    Returns
    -------
    Path
    """
    plt = _pyplot()
    s = np.flatnonzero(rs.scored)
    i, v = rs.i_ma[s], rs.v_meas_mm_s[s]
    fig, (ax, axr) = plt.subplots(2, 1, figsize=(8.0, 7.0), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    pick = np.random.default_rng(seed).permutation(s.size)[:max_points]
    ax.plot(i[pick], v[pick], ".", ms=1.5, color="0.7", alpha=0.5, label="measured samples", rasterized=True)
    cm, vm, _ = pooled_curve(i, v, curve)
    ax.plot(cm, vm, "-", color="k", lw=2.0, label="measured (local mean)")
    styles = ["--", "-", "-.", ":"]
    colors = ["tab:red", "tab:blue", "tab:green", "tab:purple"]
    for j, (label, vmod) in enumerate(curves.items()):
        c2, m2, _ = pooled_curve(i, vmod[s], curve)
        ax.plot(c2, m2, styles[j % 4], color=colors[j % 4], lw=1.6, label=label)
        cr, rr, _ = pooled_curve(i, v - vmod[s], curve)
        axr.plot(cr, rr, styles[j % 4], color=colors[j % 4], lw=1.3, label=label)
    ax.set_ylabel("velocity [mm/s]")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    axr.axhline(0.0, color="k", lw=0.8)
    axr.set_xlabel("matched current [mA]")
    axr.set_ylabel("measured - model\n(local mean) [mm/s]")
    axr.grid(alpha=0.3)
    lo, hi = (float(np.nanmin(i)), float(np.nanmax(i))) if i.size else curve.current_range_ma
    axr.set_xlim(lo - 0.3, hi + 0.3)
    return _save(fig, path)


def plot_residual_maps(rs, curves: dict, path: str | Path, *, curve: CurveConfig = CurveConfig()) -> Path:
    """Heat maps of the mean residual per (current bin, direction) cell, one panel per model."""
    plt = _pyplot()
    n = len(curves)
    fig, axes = plt.subplots(n, 1, figsize=(9.0, 1.6 + 1.4 * n), sharex=True, squeeze=False)
    edges = curve.edges
    maps = {label: cell_residuals(rs, vmod, curve) for label, vmod in curves.items()}
    vmax = max((np.nanmax(np.abs(np.where(c >= curve.min_count, m, np.nan))) for m, c in maps.values()
                if np.any(c >= curve.min_count)), default=1.0)
    vmax = float(vmax) if np.isfinite(vmax) and vmax > 0 else 1.0
    occupied = np.flatnonzero(np.any(np.concatenate([c for _, c in maps.values()]) >= curve.min_count, axis=0))
    for ax, (label, (m, c)) in zip(axes[:, 0], maps.items()):
        img = np.where(c >= curve.min_count, m, np.nan)
        mesh = ax.pcolormesh(edges, np.arange(4) - 0.5, img, cmap="RdBu_r", vmin=-vmax, vmax=vmax, shading="flat")
        ax.set_yticks(range(3))
        ax.set_yticklabels(DIRECTION_NAMES, fontsize=8)
        ax.set_title(label, fontsize=9)
        if occupied.size:
            ax.set_xlim(edges[occupied[0]] - 0.2, edges[occupied[-1] + 1] + 0.2)
    axes[-1, 0].set_xlabel("matched current [mA]")
    fig.colorbar(mesh, ax=axes[:, 0].tolist(), label="mean residual [mm/s]")
    return _save(fig, path)


def plot_regions(maps: dict, path: str | Path) -> Path:
    """Misfit score per operating-region level, one bar per model (horizontal bars, log scale)."""
    plt = _pyplot()
    labels = list(maps)
    first = maps[labels[0]]
    levels = [(lv.factor, lv.level) for lv in first.levels]
    fig, ax = plt.subplots(figsize=(8.0, 0.25 * len(levels) + 1.5))
    y = np.arange(len(levels))
    width = 0.8 / max(len(labels), 1)
    for j, label in enumerate(labels):
        vals = []
        for f, lv in levels:
            got = maps[label].level(f, lv)
            vals.append(got.score if got is not None else np.nan)
        ax.barh(y + j * width, vals, height=width, label=label)
    ax.set_yticks(y + 0.4 - width / 2)
    ax.set_yticklabels([f"{f}: {lv}" for f, lv in levels], fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_xlabel("misfit score: mean z^2 of the curve cells (1 = noise)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="x")
    return _save(fig, path)


# --------------------------------------------------------------------------- Markdown
def _fmt(x: float) -> str:
    if x is None or not np.isfinite(x):
        return "n/a"
    return f"{x:.4g}"


def calibration_summary(result) -> str:
    """Plain-text summary of a :class:`~fuelhm_bench.calibration.recalibrate.CalibrationResult`."""
    lines = [f"recalibrated on {len(result.evaluation.flight_ids)} flight(s), {len(result.unit_models)} unit(s), "
             f"frame {1e3 * result.frame_s:g} ms, N2 {'from the file' if result.n2_measured else 'constant'}",
             f"gap (RMS curve residual) before {result.gap_before:.3f} mm/s -> after {result.gap_after:.3f} mm/s "
             f"per unit, {result.gap_fleet:.3f} mm/s with the fleet model",
             f"{'parameter':38s} {'start':>12s} {'fleet value':>12s} {'std err':>10s} unit"]
    for e in result.estimates:
        lines.append(f"{e.path:38s} {e.start:12.5g} {e.value:12.5g} {e.std_error:10.2g} {e.unit}")
    worst = max(result.identifiability.values(), key=lambda i: i.condition)
    lines.append(f"identifiability: condition number {worst.condition:.1f}, largest |correlation| "
                 f"{worst.max_abs_correlation:.2f} (worst unit)")
    return "\n".join(lines)


def write_discrepancy_report(result, out_dir: str | Path, *, model_file: str, data_name: str = "") -> Path:
    """Write ``report.md``, its figures and ``result.json`` in ``out_dir`` (the caller writes the model file).

    Returns
    -------
    Path
        The report path.
    """
    out = Path(out_dir)
    curves = {"input model": result.v_heldout["input"], "recalibrated": result.v_heldout["recalibrated"]}
    if result.effect != "none":
        curves[f"recalibrated + {result.effect}"] = result.v_heldout["augmented"]
    plot_curves(result.heldout, curves, out / "curves.png", curve=result.curve,
                title=f"held-out flights: gap {result.gap_before:.3f} -> {result.gap_recalibrated:.3f} -> "
                      f"{result.gap_after:.3f} mm/s")
    maps_curves = {"recalibrated (before)": result.v_heldout["recalibrated"],
                   f"after ({result.effect})": result.v_heldout["augmented"]}
    plot_residual_maps(result.heldout, maps_curves, out / "residual_map.png", curve=result.curve)
    plot_regions({"recalibrated (before)": result.maps["recalibrated"], "after": result.maps["augmented"]},
                 out / "regions.png")
    payload = result.as_json()
    payload["model_file"] = model_file
    try:
        (out / "result.json").write_text(json_text(payload, indent=2))
    except OSError as exc:
        raise OutputPathError(f"Cannot write {out / 'result.json'}: {exc.strerror or exc}.") from None
    md = _discrepancy_markdown(result, model_file, data_name)
    path = out / "report.md"
    try:
        path.write_text(md)
    except OSError as exc:
        raise OutputPathError(f"Cannot write {path}: {exc.strerror or exc}.") from None
    return path


def _discrepancy_markdown(result, model_file: str, data_name: str) -> str:
    r = result
    lines = [f"# Model discrepancy report{': ' + data_name if data_name else ''}", ""]
    lines += [f"**Verdict: `{r.verdict}`**" + (f" -- {r.unexplained}" if r.unexplained else ""), "",
              f"**Missing effect: `{r.effect}`**" + ("" if r.effect == "none" else
              " (" + ", ".join(f"{k} = {v:.4g}" for k, v in r.parameters.items()) + ")"), ""]
    if r.effect_set:
        lines += ["| set member | parameters | approx. 95 % interval (largest correlation with a unit value) | "
                  "held at nominal | held-out gap before -> after [mm/s] | share of the gap |",
                  "|---|---|---|---|---|---|"]
        for m in r.effect_set:
            iv = "; ".join(f"{k} {d['low']:.4g}..{d['high']:.4g} ({d['max_correlation']:.2f} with {d['with']})"
                           for k, d in m.intervals.items()) or "-"
            lines.append(f"| `{m.effect}` | {', '.join(f'{k}={v:.4g}' for k, v in m.parameters.items())} | {iv} | "
                         f"{', '.join(m.held) or '-'} | {m.gap_before:.3f} -> {m.gap_after:.3f} | "
                         f"{100 * m.share:.0f} % |")
        lines.append("")
    for e in r.equivalents:
        lines += [f"**Equivalent explanation:** `{e.alternative}` explains the data about as well as `{e.selected}` "
                  f"(held-out reduction {100 * e.reduction_alternative:.0f} % vs {100 * e.reduction_selected:.0f} %, "
                  f"dBIC {e.delta_bic:.0f}). Separating test: {e.test}.", ""]
    if r.caveats:
        lines += ["**Caveats (properties of the data that weaken this verdict; they do not change it):**", ""]
        lines += [f"- `{c.code}`: {c.message}" for c in r.caveats]
        lines.append("")
    if r.flags:
        lines += ["**Recalibrated values outside the manufacturing dispersion (likely absorbing a missing effect):**",
                  "", "| unit | parameter | value | nominal | z [sigma] |", "|---|---|---|---|---|"]
        lines += [f"| {f.unit} | `{f.path}` | {f.value:.4g} | {f.nominal:.4g} | {f.z:+.1f} |" for f in r.flags]
        lines.append("")
    if r.probe is not None:
        lines += [f"**Sparse probe of the remaining residuals:** terms "
                  + (", ".join(f"{t} ({c:+.3g})" for t, c in zip(r.probe.terms, r.probe.coefficients)) or "none")
                  + f"; held-out gap {r.probe.gap_before:.3f} -> {r.probe.gap_after:.3f} mm/s "
                  f"({100 * r.probe.gap_closed:.0f} % closed).", ""]
    lines += [
              f"**Where the recalibrated model disagrees (held-out flights):** {r.region}", "",
              "| held-out gap | mm/s |", "|---|---|",
              f"| input model | {_fmt(r.gap_before)} |", f"| recalibrated | {_fmt(r.gap_recalibrated)} |",
              f"| recalibrated + `{r.effect}` | {_fmt(r.gap_after)} |",
              f"| noise floor | {_fmt(r.gap_floor)} |", "",
              f"Gap reduction on held-out flights: {100 * r.gap_reduction:.1f} % (input model to final model).", "",
              f"Gap metric: {r.gap_metric}.", "",
              "## Data", "",
              f"- fit flights ({len(r.fit_flights)}): {', '.join(map(str, r.fit_flights))}",
              f"- held-out flights ({len(r.heldout_flights)}): {', '.join(map(str, r.heldout_flights))}",
              f"- sample period {1e3 * r.frame_s:g} ms; N2 "
              f"{'from the file' if r.n2_measured else 'constant (no n2_pct column)'}",
              f"- held-out samples scored: {r.heldout.n_scored}", "",
              "## Decision", "", f"Rule: {r.decision_rule}.", "",
              f"Noise model: Gaussian residuals, sigma {r.noise.sigma_mm_s:.3f} mm/s (recalibrated model), correlation "
              f"time tau = {r.noise.tau:.1f} samples, n = {r.noise.n}, n_eff = n / tau = {r.noise.n_eff:.0f}; "
              "BIC = n_eff ln(RSS/n) + k ln(n_eff).", "",
              "| rank | effect | BIC | dBIC vs none (fitted the same way) | held-out gap [mm/s] | "
              "reduction vs recalibrated | held-out RSS reduction (log-likelihood gain) | eligible "
              "| parameters |",
              "|---|---|---|---|---|---|---|---|---|"]
    for j, c in enumerate(r.ranking, 1):
        params = ", ".join(f"{k}={v:.3g}" for k, v in c.parameters.items())
        rss = "-" if c.heldout_rss_reduction != c.heldout_rss_reduction else (
            f"{100 * c.heldout_rss_reduction:+.0f} % ({c.heldout_gain:+.0f})")
        lines.append(f"| {j} | `{c.label}` | {c.bic:.1f} | {c.delta_bic:.1f} | {c.gap_after:.3f} | "
                     f"{100 * c.gap_reduction:+.0f} % | {rss} | {'yes' if c.eligible else 'no'} | {params} |")
    lines += ["", "## Curves (held-out flights)", "", "![curves](curves.png)", "",
              "## Residual maps", "", "Mean residual (measured - model) per current bin and current direction:", "",
              "![residual map](residual_map.png)", "",
              "Misfit score (mean z^2 of the curve cells, 1 = noise) per operating region:", "",
              "![regions](regions.png)", "",
              "| factor | level | samples | score before | score after | local gap before [mm/s] "
              "| local gap after [mm/s] |",
              "|---|---|---|---|---|---|---|"]
    for lv in r.maps["recalibrated"].levels:
        after = r.maps["augmented"].level(lv.factor, lv.level)
        lines.append(f"| {lv.factor} | {lv.level} | {lv.count} | {_fmt(lv.score)} | "
                     f"{_fmt(after.score if after else np.nan)} | {_fmt(lv.local_gap_mm_s)} | "
                     f"{_fmt(after.local_gap_mm_s if after else np.nan)} |")
    lines += ["", "## Model", "",
              f"Augmented model: `{model_file}` (fleet mean of the per-unit recalibration, plus the "
              "named effect). Simulate with it:", "", "```",
              f"fuelhm-bench simulate --model {model_file} --out flights.parquet",
              "```", "", "Recalibrated parameters (fleet values):", "", "| parameter | value |", "|---|---|"]
    for p in RECALIBRATION_PARAMETERS:
        lines.append(f"| `{p.path}` | {r.model.get(p.path):.5g} {p.unit} |")
    lines += ["", f"Run time: {r.seconds:.1f} s.", ""]
    return "\n".join(lines)


def _clean(obj):
    """Make a JSON-ready structure strictly valid: numpy scalars to Python, NaN/inf to None."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def json_text(obj, *, indent: int | None = None) -> str:
    """Strict JSON text (no NaN) of a result dictionary."""
    return json.dumps(_clean(obj), indent=indent, allow_nan=False)


__all__ = ["calibration_summary", "json_text", "plot_curves", "plot_regions", "plot_residual_maps",
           "write_discrepancy_report"]
