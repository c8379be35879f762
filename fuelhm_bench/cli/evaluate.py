"""``fuelhm-bench evaluate``: run methods of the common interface on a scenario and write their KPI tables."""

from __future__ import annotations

import argparse
import sys
import time

from fuelhm_bench.cli._common import check_output_dir, non_negative_int, positive_float, progress_bar


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="evaluate detection/diagnosis methods on a scenario",
                       description="Simulate a scenario's healthy training fleet and test fleet, build the published "
                                   "knowledge (ITL, signatures), then fit and run each method (flight by flight, "
                                   "causal) and write its KPI tables (the paper's Tables V and VI, FCR, confusion, "
                                   "delays, bands, confidence intervals, robustness under drift) and a report. A "
                                   "method that raises, hangs past --timeout or returns invalid output is reported "
                                   "as such; the other methods' results are kept (exit status 3).")
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


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.evaluation import parse_params, scenario_data
    from fuelhm_bench.leaderboard import evaluate_methods, prepare_methods, write_evaluation_report
    from fuelhm_bench.scenarios import load_scenario

    out = check_output_dir(args.out)
    methods, errors = prepare_methods([(spec, {}) for spec in args.method], parse_params(args.param))
    sc = load_scenario(args.scenario)
    n = sc.training_fleet_config().n_units * sc.training_fleet_config().n_flights + \
        sc.test_fleet_config().n_units * sc.test_fleet_config().n_flights
    t0 = time.perf_counter()
    with progress_bar(n, f"simulating {sc.name}") as bar:
        data, _ = scenario_data(sc, seed=args.seed, scale=args.scale, progress=bar.update)
    t_data = time.perf_counter() - t0
    summary = errors + evaluate_methods(methods, data, out, method_seed=args.method_seed, timeout_s=args.timeout)
    table = write_evaluation_report(out, sc.id, data, summary, {"seed": args.seed, "data_seconds": round(t_data, 1)})
    print(table.to_string(index=False))
    print(f"wrote {out / 'report.md'} and {out / 'summary.json'}", file=sys.stderr)
    return 0 if all(e["status"] == "ok" for e in summary) else 3
