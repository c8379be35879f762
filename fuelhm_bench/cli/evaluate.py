"""``fuelhm-bench evaluate``: run methods of the common interface on a scenario through the environment."""

from __future__ import annotations

import argparse
import sys

from fuelhm_bench.cli._common import flight_minutes, non_negative_int, progress_bar, scale_fraction
from fuelhm_bench.cli._harness import add_run_options, limit_type, limits_from, results_dir


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="evaluate detection/diagnosis methods on a scenario",
                       description="Get the scenario's published knowledge (ITL, signatures) and healthy training "
                                   "flights (simulated once, then cached), then run each method sealed (its own "
                                   "process, limits, only the observation rows): fit, then play every unit of the "
                                   "scored fleet as an episode of FuelHM/ActuationLoop-v3 (maintenance off), the "
                                   "method deciding flight by flight. Results go to a results store (resumable); "
                                   "KPI tables (Tables V and VI, FCR, confusion, delays, bands, confidence "
                                   "intervals, robustness under drift, cost) and reports are generated from it. A "
                                   "method that fails in any way is reported with its status and message; the "
                                   "other methods' results are kept (exit status 3).")
    p.add_argument("--method", action="append", required=True, metavar="MODULE:CLASS",
                   help="method to evaluate, e.g. fuelhm_baselines.paper_mahalanobis:PaperMahalanobis (repeatable)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="hyperparameter for the methods, VALUE read as YAML (1e-3, true, [1, 2]); passed to the "
                        "constructor of every --method that has it (a name no method has is refused before "
                        "anything runs; repeatable)")
    p.add_argument("--scenario", required=True, help="scenario name or YAML file")
    p.add_argument("--fidelity", choices=("physics", "surrogate"), default=None,
                   help="simulation of the scored flights: physics (simulator + on-board extraction) or surrogate "
                        "(healthy Gaussian draws + ITL shifts, much faster); default: the scenario's")
    p.add_argument("--seed", type=non_negative_int, default=None, help="override the scenario's master seed")
    p.add_argument("--timeout", type=limit_type("wall_s"), default=600.0,
                   help="wall-time limit per method [s] (default 600)")
    p.add_argument("--scale", type=scale_fraction, default=1.0,
                   help="fraction of the scenario's test units kept, in (0, 1] (extended until every mode of the "
                        "fleet is represented)")
    p.add_argument("--minutes", type=flight_minutes, default=None,
                   help="override the flight duration [min] (quick looks; >= engine start + 1 min)")
    p.add_argument("--out", required=True, help="output directory")
    add_run_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.benchmark.leaderboard import evaluation_config, run_board
    from fuelhm_bench.benchmark.loading import parse_params

    shared = parse_params(args.param)
    if args.secret_seeds is not None and args.seed is not None:
        from fuelhm_bench.errors import ParameterError

        raise ParameterError("Give --seed or --secret-seeds, not both (--secret-seeds replaces the public seed).")
    config = evaluation_config(args.method, args.scenario, seed=args.seed, scale=args.scale, timeout_s=args.timeout,
                               fidelity=args.fidelity, limits=limits_from(args, {}),
                               secret_seeds=args.secret_seeds or 0)  # bad options: nothing created
    with results_dir(args.out, args.store, args.force) as out:
        board = run_board(config, out, store_path=args.store, shared_params=shared, rerun=args.rerun, jobs=args.jobs,
                          scheduler=args.scheduler, method_seed=args.method_seed, cache_dir=args.cache_dir,
                          flight_minutes=args.minutes, progress=progress_bar)
    cols = [c for c in ("method", "params", "status", "summary_score", "fpr_standard_thr", "fnr_standard_thr", "fcr",
                        "cost_kusd") if c in board]
    print(board[cols].to_string(index=False))
    print(f"wrote {out / 'leaderboard.md'} and one report per method under {out}", file=sys.stderr)
    return 0 if (board["status"] == "ok").all() else 3
