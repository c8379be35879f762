"""``fuelhm-bench leaderboard``: every listed method on every listed scenario, ranked; resumable, distributable."""

from __future__ import annotations

import argparse

from fuelhm_bench.cli._common import flight_minutes, progress_bar, scale_fraction
from fuelhm_bench.cli._harness import add_run_options, limit_type, limits_from, results_dir


def register(sub) -> None:
    p = sub.add_parser("leaderboard", help="run the leaderboard (methods x scenarios) and rank the methods",
                       description="Read a leaderboard file (default leaderboard/methods.yaml: methods with their "
                                   "hyperparameters, scenarios, seeds, limits), evaluate every method setting on "
                                   "every scenario and seed sealed, store each result in an SQLite results store "
                                   "and write leaderboard.md / leaderboard.csv ranked by summary score plus one "
                                   "report per scenario, seed and method setting, all generated from the store. "
                                   "Killed and started again, it evaluates only what the store is missing. Exit "
                                   "status 3 when an entry did not finish ok (its row says why; every other result "
                                   "is kept and the views are written).")
    p.add_argument("--config", default="leaderboard/methods.yaml", help="leaderboard file")
    p.add_argument("--scale", type=scale_fraction, default=None, help="override the file's test-fleet scale")
    p.add_argument("--fidelity", choices=("physics", "surrogate"), default=None, help="override the file's fidelity")
    p.add_argument("--timeout", type=limit_type("wall_s"), default=None, help="override the file's wall-time limit [s]")
    p.add_argument("--minutes", type=flight_minutes, default=None,
                   help="override every scenario's flight duration [min] (quick looks; >= engine start + 1 min)")
    p.add_argument("--out", required=True, help="output directory")
    add_run_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from fuelhm_bench.benchmark.leaderboard import LeaderboardConfig, run_board

    config = LeaderboardConfig.from_yaml(args.config)
    changes = {"scale": args.scale, "fidelity": args.fidelity, "timeout_s": args.timeout,
               "secret_seeds": args.secret_seeds}  # (replaces the file's seeds)
    config = dataclasses.replace(config, **{k: v for k, v in changes.items() if v is not None},
                                 limits=tuple(sorted(limits_from(args, dict(config.limits)).items())))
    with results_dir(args.out, args.store, args.force) as out:
        board = run_board(config, out, store_path=args.store, rerun=args.rerun, jobs=args.jobs,
                          scheduler=args.scheduler, method_seed=args.method_seed, cache_dir=args.cache_dir,
                          flight_minutes=args.minutes, progress=progress_bar)
    cols = [c for c in ("scenario", "method", "params", "status", "summary_score") if c in board]
    print(board[cols].to_string(index=False))
    print(f"wrote {out / 'leaderboard.md'} and {out / 'index.html'}")
    return 0 if (board["status"] == "ok").all() else 3
