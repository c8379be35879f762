"""``fuelhm-bench evaluate``: run methods of the common interface on a scenario through the environment."""

from __future__ import annotations

import argparse
import sys
import time

from fuelhm_bench.cli._common import check_output_dir, non_negative_int, positive_float, progress_bar


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="evaluate detection/diagnosis methods on a scenario",
                       description="Get the scenario's published knowledge (ITL, signatures) and healthy training "
                                   "flights (simulated once, then cached), fit each method, then play every unit of "
                                   "the scored fleet as an episode of FuelHM/ActuationLoop-v1 (maintenance off: "
                                   "faults evolve as scheduled), the method deciding flight by flight on the "
                                   "observation only, and write its KPI tables (the paper's Tables V and VI, FCR, "
                                   "confusion, delays, bands, confidence intervals, robustness under drift, cost "
                                   "under the scenario's cost model) and a report. A method that raises, hangs past "
                                   "--timeout or returns invalid output is reported as such; the other methods' "
                                   "results are kept (exit status 3).")
    p.add_argument("--method", action="append", required=True, metavar="MODULE:CLASS",
                   help="method to evaluate, e.g. baselines.paper_mahalanobis:PaperMahalanobis (repeatable)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="hyperparameter for the methods (applied to every --method that has it; repeatable)")
    p.add_argument("--scenario", required=True, help="scenario name or YAML file")
    p.add_argument("--fidelity", choices=("physics", "surrogate"), default=None,
                   help="simulation of the scored flights: physics (simulator + on-board extraction) or surrogate "
                        "(healthy Gaussian draws + ITL shifts, much faster); default: the scenario's")
    p.add_argument("--seed", type=non_negative_int, default=None, help="override the scenario's master seed")
    p.add_argument("--method-seed", type=non_negative_int, default=0, help="random_state passed to fit")
    p.add_argument("--timeout", type=positive_float, default=600.0, help="time limit per method [s]")
    p.add_argument("--scale", type=positive_float, default=1.0, help="multiply the number of test units (extended until every mode of the fleet is represented)")
    p.add_argument("--minutes", type=positive_float, default=None,
                   help="override the flight duration [min] (quick looks; >= engine start + 1 min)")
    p.add_argument("--cache-dir", default=None,
                   help="cache of simulated knowledge and training flights (default: $FUELHM_BENCH_CACHE or "
                        "~/.cache/fuelhm-bench)")
    p.add_argument("--out", required=True, help="output directory")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.evaluation import parse_params
    from fuelhm_bench.leaderboard import evaluate_method, evaluation_counts, prepare_methods, write_evaluation_report
    from fuelhm_bench.runner import prepare_evaluation

    out = check_output_dir(args.out)
    methods, errors = prepare_methods([(spec, {}) for spec in args.method], parse_params(args.param))
    t0 = time.perf_counter()
    with progress_bar(0, "simulating knowledge and training flights") as bar:
        def grow(n: int) -> None:  # the total is unknown: the cache may answer
            bar.total += n
            bar.update(n)

        evaluation = prepare_evaluation(args.scenario, fidelity=args.fidelity, seed=args.seed, scale=args.scale,
                                        flight_minutes=args.minutes, cache_dir=args.cache_dir, progress=grow)
    t_data = time.perf_counter() - t0
    summary = errors + [evaluate_method(spec, m, evaluation, out, method_seed=args.method_seed,
                                        timeout_s=args.timeout, progress_factory=progress_bar)
                        for spec, m in methods]
    table = write_evaluation_report(out, evaluation.scenario.id, evaluation_counts(evaluation), summary,
                                    {"seed": args.seed, "fidelity": evaluation.fidelity,
                                     "data_seconds": round(t_data, 1)})
    print(table.to_string(index=False))
    print(f"wrote {out / 'report.md'} and {out / 'summary.json'}", file=sys.stderr)
    return 0 if all(e["status"] == "ok" for e in summary) else 3
