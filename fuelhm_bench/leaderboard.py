"""Evaluate several methods on one or several scenarios and rank them (the leaderboard).

:func:`evaluate_method` is the shared core of ``fuelhm-bench evaluate`` and
``fuelhm-bench leaderboard``: it runs every method safely through the environment
(:func:`~fuelhm_bench.runner.run_in_env`), scores the ones that worked, writes
their tables and figures, and returns one summary entry per method (status,
hyperparameters, headline KPIs, robustness when the scenario drifts). A
leaderboard configuration (``leaderboard/methods.yaml``) lists methods and
scenarios; :func:`run_leaderboard` runs them all and writes ``leaderboard.md`` /
``leaderboard.csv`` ranked by the summary score (null method = 0, perfect = 100).
"""

from __future__ import annotations

import json
import re
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import yaml

from fuelhm_bench.errors import FuelHMError, ScenarioError


def slug(text: str) -> str:
    """A file-name-safe version of a method spec."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")[:80]


def prepare_methods(specs: list[tuple[str, dict]], shared_params: dict | None = None, *,
                    log: Callable[[str], object] = lambda s: print(s, file=sys.stderr)):
    """Instantiate methods; unloadable ones become error entries instead of aborting the run.

    Parameters
    ----------
    specs : list of (str, dict)
        ``module:Class`` and its own hyperparameters.
    shared_params : dict, optional
        Hyperparameters applied to every method that has them.

    Returns
    -------
    methods : list of (str, BaseMethod)
    errors : list of dict
        Summary entries of the methods that could not be built.
    """
    from fuelhm_bench.evaluation import load_method

    shared = dict(shared_params or {})
    methods, errors = [], []
    for spec, own in specs:
        try:
            m = load_method(spec, own)
            common = {k: v for k, v in shared.items() if k in m.get_params()}
            methods.append((spec, m.set_params(**common) if common else m))
        except (FuelHMError, ValueError, TypeError) as exc:
            errors.append({"method": spec, "status": "error", "seconds": 0.0, "message": f"cannot load: {exc}"})
            log(f"{spec}: ERROR: cannot load: {exc}")
    unknown = [k for k in shared if not any(k in m.get_params() for _, m in methods)]
    if unknown and methods:
        raise FuelHMError(f"--param {', '.join(unknown)}: no evaluated method has such a hyperparameter.")
    return methods, errors


def evaluate_method(spec: str, method, evaluation, out: Path, *, method_seed: int = 0, timeout_s: float = 600.0,
                    progress_factory=None, log: Callable[[str], object] = lambda s: print(s, file=sys.stderr)) -> dict:
    """Run one method through the environment (:func:`fuelhm_bench.runner.run_in_env`), score it, write its files.

    Returns its summary entry: status, hyperparameters, headline KPIs, cost under the scenario's cost
    model, robustness (for a drifting scenario), or the failure message.
    """
    from fuelhm_bench.runner import run_in_env
    from fuelhm_bench.scoring import (error_rate_changes, headline_kpis, plot_score_distributions, robustness,
                                      robustness_table,
                                      save_figure, write_tables)

    if progress_factory is not None:
        with progress_factory(evaluation.n_flights, f"{spec} ({evaluation.fidelity})") as bar:
            outcome = run_in_env(method, evaluation, random_state=method_seed, timeout_s=timeout_s,
                                 progress=bar.update)
    else:
        outcome = run_in_env(method, evaluation, random_state=method_seed, timeout_s=timeout_s)
    entry = {"method": spec, "params": {k: repr(v) for k, v in method.get_params().items()},
             "status": outcome.status, "seconds": round(outcome.seconds, 2)}
    if not outcome.ok:
        entry["message"] = outcome.message
        log(f"{spec}: {outcome.status.upper()}: {outcome.message.splitlines()[0] if outcome.message else ''}")
        return entry
    card = outcome.score()
    mdir = Path(out) / slug(spec)
    write_tables(card, mdir, overwrite=True)
    save_figure(plot_score_distributions(outcome.run(spec), card.config), mdir / "score_distributions.png")
    outcome.decisions.to_csv(mdir / "decisions.csv", index=False)
    outcome.episodes.to_csv(mdir / "episodes.csv", index=False)
    kpis = headline_kpis(card)
    kpis["cost_kusd"] = outcome.cost_kusd
    for name, value in _statistics(card, mdir, spec).items():  # (Series.update ignores new keys)
        kpis[name] = value
    if evaluation.nominal is not None:  # robustness: same method, same fleet without the drift
        nom = run_in_env(method, evaluation.nominal, random_state=method_seed, timeout_s=timeout_s)
        if nom.ok:
            nom_card = nom.score()
            kpis["robustness"] = robustness(nom_card, card)
            changes = error_rate_changes(nom_card, card)  # the two error rates, separately
            kpis["robustness_delta_fpr"], kpis["robustness_delta_fnr"] = changes["delta_fpr"], changes["delta_fnr"]
            robustness_table(nom_card, card).to_csv(mdir / "robustness.csv", index=False)
        else:
            entry["robustness_message"] = f"nominal run {nom.status}: {nom.message.splitlines()[0]}"
    entry["kpis"] = {k: (None if v != v else float(v)) for k, v in kpis.items()}
    log(f"{spec}: ok in {outcome.seconds:.1f} s; " + ", ".join(f"{k}={v:.3g}" for k, v in kpis.items() if v == v))
    return entry


def _statistics(card, mdir: Path, spec: str) -> dict:
    """Unit-bootstrap intervals and guilt calibration of a scored run (files + KPI columns)."""
    from fuelhm_bench.scoring import save_figure
    from fuelhm_bench.scoring.bootstrap import scorecard_intervals
    from fuelhm_bench.scoring.calibration import guilt_calibration, plot_reliability

    ci = scorecard_intervals(card, n_resamples=1000)
    ci.to_csv(mdir / "headline_intervals.csv", index=False)
    cal = guilt_calibration(card.flights)
    cal["reliability"].to_csv(mdir / "reliability.csv", index=False)
    save_figure(plot_reliability({spec: cal["reliability"]}), mdir / "reliability.png")
    out = {"brier": cal["brier"], "ece": cal["ece"]}
    for _, row in ci.iterrows():
        out[f"{row['kpi']}_ci_low"], out[f"{row['kpi']}_ci_high"] = row["ci_low"], row["ci_high"]
    return out


def summary_table(summary: list[dict]) -> pd.DataFrame:
    """One row per method: status and headline KPIs."""
    return pd.DataFrame([{"method": e["method"], "status": e["status"], **(e.get("kpis") or {})} for e in summary])


def write_evaluation_report(out: Path, scenario_id: str, counts: dict, summary: list[dict], meta: dict) -> pd.DataFrame:
    """Write ``summary.json`` and ``report.md`` for one scenario; returns the summary table.

    ``counts`` holds ``test``, ``fit`` and ``calibration``: numbers of flights.
    """
    from fuelhm_bench.scoring import to_markdown

    out = Path(out)
    (out / "summary.json").write_text(json.dumps({"scenario": scenario_id, **meta, "flights": counts,
                                                  "methods": summary}, indent=2))
    table = summary_table(summary)
    lines = [f"# Evaluation on `{scenario_id}`", "",
             f"{counts['test']} scored flights ({meta.get('fidelity', 'physics')} fidelity), {counts['fit']} healthy "
             f"fitting flights, {counts['calibration']} healthy calibration flights (threshold setting).", "",
             to_markdown(table.round(4)), ""]
    for e in summary:
        msg = e.get("message", "").splitlines()[0] if e.get("message") else ""
        lines.append(f"* `{e['method']}`: **{e['status']}** {msg}")
    lines += ["", "Per-method tables: one directory per method (CSV, Markdown, LaTeX).", ""]
    (out / "report.md").write_text("\n".join(lines))
    return table


def evaluation_counts(evaluation) -> dict:
    """Flight counts of an evaluation, for reports."""
    return {"test": evaluation.n_flights, "fit": len(evaluation.fit_indicators),
            "calibration": len(evaluation.calibration_indicators)}


@dataclass(frozen=True)
class LeaderboardEntry:
    """A method of the leaderboard: ``module:Class`` and its hyperparameters."""

    method: str
    params: tuple = ()


@dataclass(frozen=True)
class LeaderboardConfig:
    """What a leaderboard run evaluates.

    Parameters
    ----------
    methods : tuple of LeaderboardEntry
    scenarios : tuple of str
        Shipped names or YAML paths.
    seeds : tuple of int, default=(None,)
        Master seeds (None: the scenario's own).
    scale : float, default=1.0
        Multiplies the number of test units.
    timeout_s : float, default=900.0
        Time limit per method and scenario.
    fidelity : {"physics", "surrogate"} or None, default=None
        None: each scenario's own.
    """

    methods: tuple
    scenarios: tuple
    seeds: tuple = (None,)
    scale: float = 1.0
    timeout_s: float = 900.0
    fidelity: str | None = None

    @classmethod
    def from_yaml(cls, path) -> LeaderboardConfig:
        """Load ``leaderboard/methods.yaml`` (safe loader; errors name the file and field)."""
        path = Path(path)
        try:
            data = yaml.safe_load(path.read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise ScenarioError(f"{path}: cannot read the leaderboard file: {exc}") from None
        if not isinstance(data, dict):
            raise ScenarioError(f"{path}: a leaderboard file is a mapping with 'methods' and 'scenarios'.")
        allowed = {"methods", "scenarios", "seeds", "scale", "timeout_s", "fidelity"}
        for key in data:
            if key not in allowed:
                from fuelhm_bench.errors import did_you_mean

                raise ScenarioError(f"{path}: unknown key '{key}'. Allowed: {', '.join(sorted(allowed))}."
                                    + did_you_mean(str(key), sorted(allowed)))
        methods = []
        for i, m in enumerate(data.get("methods") or []):
            if isinstance(m, str):
                methods.append(LeaderboardEntry(m))
            elif isinstance(m, dict) and isinstance(m.get("method"), str):
                params = m.get("params") or {}
                if not isinstance(params, dict):
                    raise ScenarioError(f"{path}: methods[{i}].params must be a mapping. Got {params!r} instead.")
                methods.append(LeaderboardEntry(m["method"], tuple(sorted(params.items()))))
            else:
                raise ScenarioError(f"{path}: methods[{i}] must be 'module:Class' or {{method: ..., params: ...}}. "
                                    f"Got {m!r} instead.")
        scenarios = data.get("scenarios") or []
        if not methods or not scenarios:
            raise ScenarioError(f"{path}: 'methods' and 'scenarios' must both be non-empty lists.")
        fidelity = data.get("fidelity")
        if fidelity not in (None, "physics", "surrogate"):
            raise ScenarioError(f"{path}: fidelity must be one of physics, surrogate or null. Got {fidelity!r} instead.")
        return cls(tuple(methods), tuple(str(s) for s in scenarios), tuple(data.get("seeds") or [None]),
                   float(data.get("scale", 1.0)), float(data.get("timeout_s", 900.0)), fidelity)


def run_leaderboard(config: LeaderboardConfig, out: Path, *, progress_factory=None, cache_dir=None,
                    log: Callable[[str], object] = lambda s: print(s, file=sys.stderr)) -> pd.DataFrame:
    """Evaluate every method on every scenario and seed through the environment; write and return the ranking."""
    from fuelhm_bench.runner import prepare_evaluation
    from fuelhm_bench.scenarios import load_scenario
    from fuelhm_bench.scoring import to_markdown

    out = Path(out)
    rows = []
    for scenario in config.scenarios:
        sc = load_scenario(scenario)
        for seed in config.seeds:
            t0 = time.perf_counter()
            evaluation = prepare_evaluation(sc, fidelity=config.fidelity, seed=seed, scale=config.scale,
                                            cache_dir=cache_dir)
            sdir = out / f"{sc.id}-seed{seed if seed is not None else sc.seeds.master}"
            sdir.mkdir(parents=True, exist_ok=True)
            methods, errors = prepare_methods([(m.method, dict(m.params)) for m in config.methods], log=log)
            summary = errors + [evaluate_method(spec, m, evaluation, sdir, timeout_s=config.timeout_s,
                                                progress_factory=progress_factory, log=log) for spec, m in methods]
            write_evaluation_report(sdir, sc.id, evaluation_counts(evaluation), summary,
                                    {"seed": seed, "fidelity": evaluation.fidelity,
                                     "seconds": round(time.perf_counter() - t0, 1)})
            for e in summary:
                files = {"report": f"{sdir.name}/report.md"}
                files.update({name: f"{sdir.name}/{slug(e['method'])}/{f}" for name, f in (
                    ("detection", "table_v_detection.md"), ("scores", "score_distributions.png"),
                    ("reliability", "reliability.png"), ("intervals", "headline_intervals.csv"))})
                rows.append({"scenario": sc.id, "seed": seed if seed is not None else sc.seeds.master,
                             "fidelity": evaluation.fidelity, "method": e["method"], "status": e["status"],
                             "params": ", ".join(f"{k}={v}" for k, v in sorted((e.get("params") or {}).items())),
                             "message": (e.get("message") or "").strip().splitlines()[0] if e.get("message")
                             else "", "links": files, **(e.get("kpis") or {})})
    board = pd.DataFrame(rows)
    from fuelhm_bench.leaderboard_page import write_leaderboard_page

    write_leaderboard_page(board, out)  # index.html: a view of the same rows
    board = board.drop(columns=["links"], errors="ignore")
    if "summary_score" in board:
        board = board.sort_values(["scenario", "summary_score"], ascending=[True, False], na_position="last")
    board.to_csv(out / "leaderboard.csv", index=False)
    cols = [c for c in ("scenario", "seed", "method", "params", "status", "summary_score",
                        "summary_score_ci_low", "summary_score_ci_high", "fpr_standard_thr",
                        "fnr_standard_thr", "fcr", "brier", "delay_censored_mean", "cost_kusd", "robustness",
                        "robustness_delta_fpr", "robustness_delta_fnr")
            if c in board]
    (out / "leaderboard.md").write_text("# Leaderboard\n\nRanked by summary score (null method = 0, perfect = 100; "
                                        "docs/scoring.md).\n\n" + to_markdown(board[cols].round(3)) + "\n")
    return board
