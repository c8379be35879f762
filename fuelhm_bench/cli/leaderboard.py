"""``fuelhm-bench leaderboard``: every listed method on every listed scenario, ranked."""

from __future__ import annotations

import argparse

from fuelhm_bench.cli._common import check_output_dir, positive_float, progress_bar


def register(sub) -> None:
    p = sub.add_parser("leaderboard", help="run the leaderboard (methods x scenarios) and rank the methods",
                       description="Read a leaderboard file (default leaderboard/methods.yaml: methods with their "
                                   "hyperparameters, scenarios, seeds), evaluate every method on every scenario "
                                   "and seed, and write leaderboard.md / leaderboard.csv ranked by summary score, "
                                   "plus one evaluation directory per scenario and seed.")
    p.add_argument("--config", default="leaderboard/methods.yaml", help="leaderboard file")
    p.add_argument("--scale", type=positive_float, default=None, help="override the file's test-fleet scale")
    p.add_argument("--fidelity", choices=("physics", "surrogate"), default=None, help="override the file's fidelity")
    p.add_argument("--cache-dir", default=None, help="cache of simulated knowledge and flights")
    p.add_argument("--out", required=True, help="output directory")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from fuelhm_bench.leaderboard import LeaderboardConfig, run_leaderboard

    config = LeaderboardConfig.from_yaml(args.config)
    if args.scale is not None:
        config = dataclasses.replace(config, scale=args.scale)
    if args.fidelity is not None:
        config = dataclasses.replace(config, fidelity=args.fidelity)
    out = check_output_dir(args.out)
    board = run_leaderboard(config, out, progress_factory=progress_bar, cache_dir=args.cache_dir)
    cols = [c for c in ("scenario", "method", "status", "summary_score") if c in board]
    print(board[cols].to_string(index=False))
    print(f"wrote {out / 'leaderboard.md'} and {out / 'index.html'}")
    return 0
