"""``fuelhm-bench drift-sweep``: robustness of one method, one drifted parameter at a time."""

from __future__ import annotations

import argparse
import json
import sys

from fuelhm_bench.cli._common import (check_output_dir, non_negative_int, positive_float, positive_int, progress_bar,
                                      scale_fraction)
from fuelhm_bench.cli._harness import limit_type
from fuelhm_bench.io.outputs import claim, refuse_foreign


def register(sub) -> None:
    p = sub.add_parser("drift-sweep", help="sweep nominal-parameter drift one parameter at a time (robustness)",
                       description="Fit and calibrate a method on a scenario's healthy training flights, run it on "
                                   "the scored fleet without drift and with each parameter drifted alone by each "
                                   "magnitude (same units and flights), and write the change of the false-positive "
                                   "and false-negative rates (drift_sweep.csv, drift_sweep.md) and, per parameter, "
                                   "the drift at which either rate rises by more than --tolerance "
                                   "(drift_summary.csv).")
    p.add_argument("--method", required=True, metavar="MODULE:CLASS",
                   help="method, e.g. baselines.paper_mahalanobis:PaperMahalanobis")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="hyperparameter (repeatable)")
    p.add_argument("--scenario", required=True, help="scenario name or YAML file (its own drift is ignored)")
    p.add_argument("--parameters", required=True,
                   help="comma-separated model parameter paths, e.g. fluid.supply_rise_at_100pct_pa")
    p.add_argument("--magnitudes", default="0.05,0.1,0.2",
                   help="comma-separated drifts, at least three (default 0.05,0.1,0.2)")
    p.add_argument("--change", choices=("relative", "absolute"), default="relative",
                   help="relative: x (1 + m); absolute: + m in SI units (default relative)")
    p.add_argument("--tolerance", type=positive_float, default=0.05,
                   help="degradation threshold: a rise of FPR or FNR by more than this (default 0.05)")
    p.add_argument("--scale", type=scale_fraction, default=1.0, help="fraction of the scored units kept, in (0, 1]")
    p.add_argument("--doe-units", type=positive_int, default=6, help="units of the ITL design (default 6)")
    p.add_argument("--seed", type=non_negative_int, default=None, help="override the scenario's master seed")
    p.add_argument("--timeout", type=limit_type("wall_s"), default=600.0, help="time limit per run [s]")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--force", action="store_true",
                   help="replace files in --out that fuelhm-bench did not write (its own earlier output is "
                        "replaced without it)")
    p.set_defaults(func=run)


OUTPUT_FILES = ("drift_sweep.csv", "drift_summary.csv", "drift_sweep.md", "drift_sweep.json")


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.benchmark.drift_sweep import DriftSweep, check_sweep, run_drift_sweep
    from fuelhm_bench.errors import ParameterError
    from fuelhm_bench.benchmark.loading import parse_params
    from fuelhm_bench.methods.loading import load_method

    try:
        magnitudes = tuple(float(x) for x in args.magnitudes.split(","))
    except ValueError:
        raise ParameterError(f"--magnitudes must be comma-separated numbers. Got '{args.magnitudes}'.") from None
    parameters = tuple(x.strip() for x in args.parameters.split(",") if x.strip())
    sweep = DriftSweep(parameters=parameters, magnitudes=magnitudes, change=args.change, tolerance=args.tolerance)
    check_sweep(sweep, args.scenario, names={"parameters": "--parameters", "magnitudes": "--magnitudes"})
    method = load_method(args.method, parse_params(args.param))
    out = check_output_dir(args.out)  # (after every option check: a refused command creates nothing)
    refuse_foreign(out, OUTPUT_FILES, force=args.force)
    claim(out, OUTPUT_FILES)  # (before writing: a failed run leaves nothing of the user's unprotected)
    with progress_bar(0, "simulating") as bar:
        def grow(n: int) -> None:
            bar.total += n
            bar.update(n)

        result = run_drift_sweep(method, args.scenario, sweep, scale=args.scale, doe_units=args.doe_units,
                                 seed=args.seed, timeout_s=args.timeout, progress=grow)
    result.table.to_csv(out / "drift_sweep.csv", index=False)
    result.summary.to_csv(out / "drift_summary.csv", index=False)
    (out / "drift_sweep.md").write_text(result.to_markdown() + "\n")
    (out / "drift_sweep.json").write_text(json.dumps({"method": result.method, "summary": result.summary["summary"].tolist()},
                                                     indent=1) + "\n")
    print(result.to_markdown())
    print(f"wrote drift_sweep.csv, drift_summary.csv, drift_sweep.md, drift_sweep.json to {out}", file=sys.stderr)
    return 0
