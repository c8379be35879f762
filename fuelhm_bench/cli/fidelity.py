"""``fuelhm-bench fidelity``: does the surrogate fidelity rank methods as the physics does?"""

from __future__ import annotations

import argparse
import sys

from fuelhm_bench.cli._common import check_output_dir, flight_minutes, non_negative_int, scale_fraction
from fuelhm_bench.cli._harness import limit_type


def register(sub) -> None:
    p = sub.add_parser("fidelity", help="compare a panel of methods at physics and surrogate fidelity",
                       description="Evaluate a reference panel of methods (the shipped baselines and detectors "
                                   "with different inductive biases, or the --method given) on each scenario at "
                                   "both fidelities, and report Kendall's tau between the two rankings of the "
                                   "summary scores, each method's summary-score difference and the per-mode "
                                   "detection and false-classification differences, with a figure. Targets: "
                                   "tau >= 0.8, |summary diff| <= 5 points, |FCR diff| <= 0.05. Run from the "
                                   "repository root (the panel lives in baselines/). Exit status 0 when every "
                                   "target is met, 4 when one is not (the report says which).")
    p.add_argument("--scenario", action="append", required=True,
                   help="scenario name or YAML file (repeatable; 'all' = every shipped scenario)")
    p.add_argument("--method", action="append", default=None, metavar="MODULE:CLASS",
                   help="method of the panel (repeatable, at least two); default: the reference panel")
    p.add_argument("--seed", type=non_negative_int, default=None, help="override the scenarios' master seed")
    p.add_argument("--noise-seed", type=non_negative_int, default=None,
                   help="also run the panel at physics fidelity with this master seed and report how far apart "
                        "the two physics runs are (the noise floor of the comparison; costs a second physics run)")
    p.add_argument("--method-seed", type=non_negative_int, default=0, help="random_state passed to fit")
    p.add_argument("--timeout", type=limit_type("wall_s"), default=600.0, help="time limit per method run [s]")
    p.add_argument("--scale", type=scale_fraction, default=1.0, help="fraction of the scored units kept, in (0, 1]")
    p.add_argument("--minutes", type=flight_minutes, default=None,
                   help="override the flight duration [min] (quick looks; >= engine start + 1 min)")
    p.add_argument("--cache-dir", default=None,
                   help="cache of simulated flights (default: $FUELHM_BENCH_CACHE or ~/.cache/fuelhm-bench)")
    p.add_argument("--out", required=True, help="output directory (one sub-directory per scenario + table.md)")
    p.add_argument("--force", action="store_true",
                   help="replace files in --out that fuelhm-bench did not write (its own earlier output is "
                        "replaced without it)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    from fuelhm_bench.errors import ParameterError
    from fuelhm_bench.methods.loading import load_method
    from fuelhm_bench.benchmark.fidelity import fidelity_check

    from fuelhm_bench.datasets.cache import resolve_scenario
    from fuelhm_bench.io.outputs import claim, refuse_foreign

    scenarios = list(args.scenario)
    if "all" in scenarios:
        from fuelhm_bench.scenarios import list_scenarios

        scenarios = [s for s in scenarios if s != "all"] + list(list_scenarios())
    ids = [resolve_scenario(s).id for s in dict.fromkeys(scenarios)]  # every name checked before anything runs
    methods = None
    if args.method:
        if len(set(args.method)) < 2:
            raise ParameterError(f"--method must name at least two different methods (a ranking needs two). "
                                 f"Got {args.method} instead.")
        methods = {spec.rpartition(":")[2] if args.method.count(spec) == 1 else spec: load_method(spec)
                   for spec in dict.fromkeys(args.method)}
    out = check_output_dir(args.out)  # (after every option check: a refused command creates nothing)
    names = ("table.md", "table.csv", *ids)
    refuse_foreign(out, names, force=args.force)
    claim(out, names)
    rows = []
    for scenario in dict.fromkeys(scenarios):
        report = fidelity_check(scenario, methods=methods, seed=args.seed, scale=args.scale,
                                flight_minutes=args.minutes, cache_dir=args.cache_dir,
                                random_state=args.method_seed, timeout_s=args.timeout, noise_seed=args.noise_seed,
                                progress=lambda line: print(line, file=sys.stderr, flush=True))
        report.write(out / report.scenario)
        rows.append(report.summary())
        print(report.to_markdown())
    table = pd.DataFrame(rows)
    from fuelhm_bench.benchmark.fidelity import _markdown

    (out / "table.md").write_text(_markdown(table) + "\n", encoding="utf-8")
    table.to_csv(out / "table.csv", index=False)
    print(_markdown(table))
    print(f"wrote {out / 'table.md'} and one directory per scenario", file=sys.stderr)
    return 0 if (table["verdict"] == "pass").all() else 4
