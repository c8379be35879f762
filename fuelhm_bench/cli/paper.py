"""``fuelhm-bench paper``: the paper's study end to end, tables beside the published values."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fuelhm_bench.cli._common import atomic_directory, positive_int, progress_bar, scale_fraction


def register(sub) -> None:
    p = sub.add_parser("paper", help="reproduce the paper's Tables IV-VI and figures (the main job)",
                       description="Run the study of Lamoureux, Masse & Mechbal (2012) on scenarios/paper_2012.yaml: "
                                   "healthy fleet, ITL, signature matrix, Mahalanobis detection, collinearity "
                                   "diagnosis; print Tables IV, V and VI beside the published values; write "
                                   "table_iv.csv, table_v.csv, table_vi.csv, figures (Figs. 4, 5, 8, 10) and "
                                   "report.md to --out.")
    p.add_argument("--scenario", default="paper_2012", help="scenario name or YAML file (default paper_2012)")
    p.add_argument("--doe-units", type=positive_int, default=8, help="units of the ITL design of experiments")
    p.add_argument("--scale", type=scale_fraction, default=1.0,
                   help="shrink the fleets (e.g. 0.2 for a quick look); 1 = the scenario as written")
    p.add_argument("--cache-dir", default=None, help="cache of simulated knowledge and flights")
    p.add_argument("--jobs", type=positive_int, default=None,
                   help="processes simulating in parallel (default: every CPU available); results do not depend on it")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--force", action="store_true",
                   help="replace files in --out that fuelhm-bench did not write (its own earlier output is "
                        "replaced without it)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.benchmark.paper import run_paper
    from fuelhm_bench.benchmark.paper_report import OUTPUT_FILES, model_figures, print_tables, write_outputs
    from fuelhm_bench.datasets.parallel import check_workers, submit
    from fuelhm_bench.scenarios import load_scenario

    out = Path(args.out)
    sc = load_scenario(args.scenario)
    workers = check_workers(args.jobs, "--jobs")
    # checked now (a user's file of the same name, before the study); nothing is published unless every file is written
    with atomic_directory(out, force=args.force, expected=OUTPUT_FILES) as tmp:
        # Figs. 4, 5 and 8 do not depend on the study: drawn on a core as soon as one is free.
        figures = submit(model_figures, sc.test_fleet_config().mission, tmp, workers=workers)
        with progress_bar(0, "paper study") as bar:
            def grow(n: int) -> None:  # the total is unknown: the cache may answer
                bar.total += n
                bar.update(n)

            result = run_paper(sc, doe_units=args.doe_units, scale=args.scale, progress=grow,
                               cache_dir=args.cache_dir, workers=workers,
                               on_stage=lambda s: bar.set_postfix_str(s[:40]) if not bar.disable
                               else print(f"[paper] {s}", file=sys.stderr))
        print_tables(result)
        paths = write_outputs(result, tmp, figures.result())
    print(f"\nwrote {len(paths)} files to {out} (report: {out / 'report.md'}); "
          f"total {result.timings['total_s']:.1f} s")
    return 0
