"""``fuelhm-bench evaluate``: run methods of the common interface on a scenario and write their KPI tables."""

from __future__ import annotations

import argparse
import json
import re
import sys
import time

from fuelhm_bench.cli._common import check_output_dir, non_negative_int, positive_float, progress_bar


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="evaluate detection/diagnosis methods on a scenario",
                       description="Simulate a scenario's healthy training fleet and test fleet, build the published "
                                   "knowledge (ITL, signatures), then fit and run each method (flight by flight, "
                                   "causal) and write its KPI tables (the paper's Tables V and VI, FCR, confusion, "
                                   "delays, bands, confidence intervals) and a report. A method that raises, hangs "
                                   "past --timeout or returns invalid output is reported as such; the other "
                                   "methods' results are kept.")
    p.add_argument("--method", action="append", required=True, metavar="MODULE:CLASS",
                   help="method to evaluate, e.g. baselines.paper_mahalanobis:PaperMahalanobis (repeatable)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="hyperparameter for the methods (applied to every --method that has it; repeatable)")
    p.add_argument("--scenario", required=True, help="scenario name or YAML file")
    p.add_argument("--seed", type=non_negative_int, default=None, help="override the scenario's master seed")
    p.add_argument("--method-seed", type=non_negative_int, default=0, help="random_state passed to fit")
    p.add_argument("--timeout", type=positive_float, default=600.0, help="time limit per method [s]")
    p.add_argument("--scale", type=positive_float, default=1.0, help="multiply the number of test units")
    p.add_argument("--out", required=True, help="output directory")
    p.set_defaults(func=run)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")[:80]


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.evaluation import load_method, parse_params, run_method, scenario_data, score_outcome
    from fuelhm_bench.scoring import headline_kpis, plot_score_distributions, save_figure, to_markdown, write_tables

    out = check_output_dir(args.out)
    params = parse_params(args.param)
    from fuelhm_bench.errors import FuelHMError

    methods, summary = [], []
    for spec in args.method:
        try:
            m = load_method(spec)
            own = {k: v for k, v in params.items() if k in m.get_params()}
            methods.append((spec, m.set_params(**own) if own else m))
        except (FuelHMError, ValueError, TypeError) as exc:  # reported, the other methods still run
            summary.append({"method": spec, "status": "error", "seconds": 0.0, "message": f"cannot load: {exc}"})
            print(f"{spec}: ERROR: cannot load: {exc}", file=sys.stderr)
    unknown = [k for k in params if not any(k in m.get_params() for _, m in methods)]
    if unknown and methods:
        raise FuelHMError(f"--param {', '.join(unknown)}: no evaluated method has such a hyperparameter.")
    from fuelhm_bench.scenarios import load_scenario

    sc = load_scenario(args.scenario)
    n = sc.training_fleet_config().n_units * sc.training_fleet_config().n_flights + \
        sc.test_fleet_config().n_units * sc.test_fleet_config().n_flights
    t0 = time.perf_counter()
    with progress_bar(n, f"simulating {sc.name}") as bar:
        data, _ = scenario_data(sc, seed=args.seed, scale=args.scale, progress=bar.update)
    t_data = time.perf_counter() - t0
    for spec, method in methods:
        outcome = run_method(method, data, random_state=args.method_seed, timeout_s=args.timeout)
        entry = {"method": spec, "params": {k: repr(v) for k, v in method.get_params().items()},
                 "status": outcome.status, "seconds": round(outcome.seconds, 2)}
        mdir = out / _slug(spec)
        if outcome.ok:
            card = score_outcome(outcome, data)
            write_tables(card, mdir, overwrite=True)
            from fuelhm_bench.scoring import Run

            run_ = Run(labels=data.test_labels, decisions=outcome.decisions, healthy_scores=outcome.healthy_scores,
                       name=spec)
            save_figure(plot_score_distributions(run_, card.config), mdir / "score_distributions.png")
            outcome.decisions.to_csv(mdir / "decisions.csv", index=False)
            kpis = headline_kpis(card)
            if data.nominal is not None:  # robustness: same method, same fleet without the drift
                from fuelhm_bench.scoring import robustness, robustness_table

                nom = run_method(method, data.nominal, random_state=args.method_seed, timeout_s=args.timeout)
                if nom.ok:
                    nom_card = score_outcome(nom, data.nominal)
                    kpis["robustness"] = robustness(nom_card, card)
                    robustness_table(nom_card, card).to_csv(mdir / "robustness.csv", index=False)
                else:
                    entry["robustness_message"] = f"nominal run {nom.status}: {nom.message.splitlines()[0]}"
            entry["kpis"] = {k: (None if v != v else float(v)) for k, v in kpis.items()}
            print(f"{spec}: ok in {outcome.seconds:.1f} s; " +
                  ", ".join(f"{k}={v:.3g}" for k, v in kpis.items() if v == v), file=sys.stderr)
        else:
            entry["message"] = outcome.message
            first = outcome.message.splitlines()[0] if outcome.message else ""
            print(f"{spec}: {outcome.status.upper()}: {first}", file=sys.stderr)
        summary.append(entry)
    (out / "summary.json").write_text(json.dumps({"scenario": sc.id if hasattr(sc, "id") else sc.name,
                                                  "seed": args.seed, "data_seconds": round(t_data, 1),
                                                  "methods": summary}, indent=2))
    import pandas as pd

    rows = [{"method": e["method"], "status": e["status"], **(e.get("kpis") or {})} for e in summary]
    table = pd.DataFrame(rows)
    (out / "report.md").write_text(
        f"# Evaluation on `{sc.name}`\n\n{len(data.test_indicators)} test flights, "
        f"{len(data.fit_indicators)} healthy fitting flights, {len(data.calibration_indicators)} healthy "
        f"calibration flights (threshold setting).\n\n" + to_markdown(table.round(4)) + "\n\n" +
        "".join(f"* `{e['method']}`: **{e['status']}** {e.get('message', '').splitlines()[0] if e.get('message') else ''}\n"
                for e in summary) + "\nPer-method tables: one directory per method (CSV, Markdown, LaTeX).\n")
    print(table.to_string(index=False))
    print(f"wrote {out / 'report.md'} and {out / 'summary.json'}")
    return 0 if all(e["status"] == "ok" for e in summary) else 3
