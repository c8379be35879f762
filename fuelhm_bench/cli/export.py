"""``fuelhm-bench export``: a scenario's tables as Parquet, for methods outside this package."""

from __future__ import annotations

import argparse

from fuelhm_bench.cli._common import flight_minutes, non_negative_int, scale_fraction


def register(sub) -> None:
    p = sub.add_parser("export", help="write a scenario's training/test indicators and labels as Parquet",
                       description="Write training.parquet (healthy training indicators, split = fit or "
                                   "calibration), test.parquet (indicators of the scored fleet), labels.parquet "
                                   "(its ground truth) and, with --raw, the full-rate raw flights, from the "
                                   "simulation cache. Score the decisions of an external method with "
                                   "'fuelhm-bench score'. Formats: docs/scoring.md, 'External methods'.")
    add_scenario_options(p)
    p.add_argument("--raw", action="store_true",
                   help="also write raw_training.parquet and raw_test.parquet (full-rate samples; physics only)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    p.set_defaults(func=run)


def add_scenario_options(p) -> None:
    """Options that select a scenario's data (shared by export and score: use the same values)."""
    p.add_argument("--scenario", required=True, help="scenario name or YAML file")
    p.add_argument("--fidelity", choices=("physics", "surrogate"), default=None,
                   help="simulation of the scored flights; default: the scenario's")
    p.add_argument("--seed", type=non_negative_int, default=None, help="override the scenario's master seed")
    p.add_argument("--scale", type=scale_fraction, default=1.0,
                   help="multiply the number of test units (extended until every mode is represented)")
    p.add_argument("--minutes", type=flight_minutes, default=None, help="override the flight duration [min]")
    p.add_argument("--cache-dir", default=None, help="cache of simulated products")


def scenario_kwargs(args: argparse.Namespace) -> dict:
    return {"fidelity": args.fidelity, "seed": args.seed, "scale": args.scale,
            "flight_minutes": args.minutes, "cache_dir": args.cache_dir}


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.cli._common import check_output_dir
    from fuelhm_bench.datasets.cache import resolve_scenario
    from fuelhm_bench.benchmark.exchange import export_scenario

    resolve_scenario(args.scenario)  # a bad scenario fails before any directory is created
    out = check_output_dir(args.out)
    paths = export_scenario(args.scenario, out, raw=args.raw, force=args.force, **scenario_kwargs(args))
    for name, path in paths.items():
        print(f"{name}: {path}")
    return 0
