"""``fuelhm-bench itl``: design of experiments, the 70 indicator transformation laws and the signature matrix."""

from __future__ import annotations

import argparse
import time

from fuelhm_bench.cli._common import check_output_dir, non_negative_int, positive_float, positive_int, progress_bar


def register(sub) -> None:
    p = sub.add_parser("itl", help="compute the indicator transformation laws (ITL) and the signature matrix",
                       description="Simulate the design of experiments (every unit flies the same flight healthy "
                                   "and with each degradation at increasing intensities), fit the 70 linear laws "
                                   "dI = A * intensity (paper eqs. 2-5), fit the healthy model on a healthy fleet "
                                   "and write itl.csv, signatures.csv/.md (Table IV, eq. 9) and plots.")
    p.add_argument("--scenario", default=None,
                   help="scenario name or YAML file: mission, sensor and dispersion of its training fleet")
    p.add_argument("--units", type=positive_int, default=8, help="DOE units (default 8)")
    p.add_argument("--intensities", default="0.25,0.5,0.75,1", help="comma-separated intensities in (0, 1]")
    p.add_argument("--minutes", type=positive_float, default=None, help="flight duration [min] (default 15)")
    p.add_argument("--healthy-units", type=positive_int, default=8, help="units of the healthy fleet (default 8)")
    p.add_argument("--healthy-flights", type=positive_int, default=5, help="flights per healthy unit (default 5)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="master seed (default 0)")
    p.add_argument("--out", required=True, help="output directory")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.errors import ParameterError
    from fuelhm_bench.datasets.knowledge import KnowledgeBuild, build_knowledge, write_knowledge

    out = check_output_dir(args.out)
    try:
        intensities = tuple(float(x) for x in args.intensities.split(","))
    except ValueError:
        raise ParameterError(f"--intensities must be comma-separated numbers in (0, 1]. Got '{args.intensities}'.") from None
    build = KnowledgeBuild.from_scenario(args.scenario, doe_units=args.units, intensities=intensities,
                                         minutes=args.minutes, healthy_units=args.healthy_units,
                                         healthy_flights=args.healthy_flights, seed=args.seed)
    t0 = time.perf_counter()
    with progress_bar(build.n_flights, "ITL design of experiments") as bar:
        result = build_knowledge(build, progress=bar.update)
    paths = write_knowledge(result, out)
    n_bad = int((result.itl.table["r2"] < 0.8).sum())
    print(f"{len(result.itl.table)} laws ({n_bad} with r2 < 0.8) from {build.n_flights} flights in "
          f"{time.perf_counter() - t0:.1f} s; wrote {', '.join(p.name for p in paths)} to {out}")
    return 0
