"""``fuelhm-bench itl``: design of experiments, the 70 indicator transformation laws and the signature matrix."""

from __future__ import annotations

import argparse
import time

from fuelhm_bench.cli._common import atomic_directory, bounded, check_run_budget, non_negative_int, progress_bar


def register(sub) -> None:
    p = sub.add_parser("itl", help="compute the indicator transformation laws (ITL) and the signature matrix",
                       description="Simulate the design of experiments (every unit flies the same flight healthy "
                                   "and with each degradation at increasing intensities), fit the 70 linear laws "
                                   "dI = A * intensity (paper eqs. 2-5), fit the healthy model on a healthy fleet "
                                   "and write itl.csv, signatures.csv/.md (Table IV, eq. 9), plots and the diagnosability "
                                   "report (largest |Z| per mode, R2 of the linear and monotone laws, cosine "
                                   "similarity of the signatures; paper's ten and extended indicators).")
    p.add_argument("--scenario", default=None,
                   help="scenario name or YAML file: mission, sensor and dispersion of its training fleet")
    p.add_argument("--units", type=bounded(int, 1, 10_000), default=8, help="DOE units (default 8)")
    p.add_argument("--intensities", default="0.25,0.5,0.75,1",
                   help="comma-separated intensities in (0, 1], at least two distinct (default 0.25,0.5,0.75,1)")
    p.add_argument("--minutes", type=bounded(float, 2.0, 1440.0, "min"), default=None,
                   help="flight duration [min], in [2, 1440] (default 15)")
    p.add_argument("--healthy-units", type=bounded(int, 1, 10_000), default=8, help="units of the healthy fleet (default 8)")
    p.add_argument("--healthy-flights", type=bounded(int, 1, 10_000), default=5, help="flights per healthy unit (default 5)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="master seed (default 0)")
    p.add_argument("--jobs", type=bounded(int, 1, 1024), default=None,
                   help="processes simulating in parallel (default: every CPU available); results do not depend on it")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--force", action="store_true",
                   help="replace files in --out that fuelhm-bench did not write (its own earlier output is "
                        "replaced without it)")
    p.set_defaults(func=run)


#: The files ``fuelhm-bench itl`` writes into ``--out`` (``write_knowledge`` and :func:`write_diagnosability`).
OUTPUT_FILES = ("itl.csv", "signatures.csv", "signatures.md", "healthy_indicators.csv", "doe_indicators.csv", "itl.png",
                "signatures.png", "diagnosability.md", "diagnosability_paper.md", "diagnosability_paper.json",
                "diagnosability_paper_laws.csv", "diagnosability_extended.md", "diagnosability_extended.json",
                "diagnosability_extended_laws.csv")


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.errors import ParameterError
    from fuelhm_bench.datasets.knowledge import KnowledgeBuild, build_knowledge, write_knowledge
    from fuelhm_bench.datasets.parallel import check_workers

    try:
        intensities = tuple(float(x) for x in args.intensities.split(","))
    except ValueError:
        intensities = (float("nan"),)
    if not all(0.0 < x <= 1.0 for x in intensities):
        raise ParameterError(f"--intensities must be comma-separated numbers in (0, 1]. Got '{args.intensities}' "
                             "instead.")
    if len(set(intensities)) < 2:  # (one intensity fits every law exactly through it: each R2 would read 0)
        raise ParameterError(f"--intensities must hold at least two distinct values in (0, 1]: a law's R2 measures "
                             f"how linear the response is across intensities. Got '{args.intensities}' instead.")
    from fuelhm_bench.taxonomy import INDICATOR_NAMES

    needed = len(INDICATOR_NAMES) + 1  # the healthy Gaussian model of the ten indicators
    if args.healthy_units * args.healthy_flights < needed:
        raise ParameterError(f"--healthy-units x --healthy-flights must give at least {needed} healthy flights (the "
                             f"healthy model of {len(INDICATOR_NAMES)} indicators). Got {args.healthy_units} x "
                             f"{args.healthy_flights} = {args.healthy_units * args.healthy_flights} instead.")
    build = KnowledgeBuild.from_scenario(args.scenario, doe_units=args.units, intensities=intensities,
                                         minutes=args.minutes, healthy_units=args.healthy_units,
                                         healthy_flights=args.healthy_flights, seed=args.seed)
    mission = build.doe.mission
    minutes = mission.duration_s / 60.0
    cases = len(build.doe.cases())
    check_run_budget(1, build.n_flights, minutes, 1.0 / mission.frame_s,
                     what=f"--units {args.units} x {cases} cases (healthy + {len(build.doe.modes)} modes x "
                          f"{len(intensities)} intensities) + --healthy-units {args.healthy_units} x "
                          f"--healthy-flights {args.healthy_flights} = {build.n_flights} flights of {minutes:g} min")
    t0 = time.perf_counter()
    # checked now (a user's file of the same name, before the simulation); nothing is published unless every file is written
    with atomic_directory(args.out, force=args.force, expected=OUTPUT_FILES) as tmp:
        with progress_bar(build.n_flights, "ITL design of experiments") as bar:
            result = build_knowledge(build, progress=bar.update, workers=check_workers(args.jobs, "itl"))
        paths = write_knowledge(result, tmp)
        paths += write_diagnosability(result, tmp)
    n_bad = int((result.itl.table["r2"] < 0.8).sum())
    print(f"{len(result.itl.table)} laws ({n_bad} with r2 < 0.8) from {build.n_flights} flights in "
          f"{time.perf_counter() - t0:.1f} s; wrote {', '.join(p.name for p in paths)} to {args.out}")
    return 0


def write_diagnosability(result, out) -> list:
    """Write the diagnosability reports of the paper's ten and of the extended set, and their summary.

    ``diagnosability.md`` holds both tables; ``diagnosability_paper.*`` and
    ``diagnosability_extended.*`` the full content (JSON, every law's R² in CSV).
    """
    from pathlib import Path

    from fuelhm_bench.diagnosis.diagnosability import diagnosability_report
    from fuelhm_bench.taxonomy import ALL_INDICATOR_NAMES, INDICATOR_NAMES

    reports = [diagnosability_report(result.doe_table, result.healthy_table, features=features,
                                     max_intensity=result.max_intensity, name=name)
               for name, features in (("paper", INDICATOR_NAMES), ("extended", ALL_INDICATOR_NAMES))]
    paths = []
    for report in reports:
        paths += report.write(out)
    summary = Path(out) / "diagnosability.md"
    summary.write_text("# Diagnosability of the degradation modes\n\n" +
                       "\n\n".join(r.to_markdown() for r in reports) + "\n")
    for r in reports:
        weak = [m for m, v in zip(r.modes["mode"], r.modes["visible"]) if not v]
        pairs = ", ".join(f"{a}/{b} {c:.2f}" for a, b, c in r.similar_pairs()) or "none"
        print(f"diagnosability ({r.name}, {len(r.features)} indicators): modes below |Z| {r.z_target:g}: "
              f"{', '.join(weak) or 'none'}; signature pairs with cosine > {r.cosine_limit:g}: {pairs}")
    return [summary, *paths]
