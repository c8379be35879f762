"""``fuelhm-bench score``: score an externally produced decisions file against a scenario."""

from __future__ import annotations

import argparse

from fuelhm_bench.cli.export import add_scenario_options, scenario_kwargs


def register(sub) -> None:
    p = sub.add_parser("score", help="score a decisions file (Parquet or CSV) produced outside this package",
                       description="Score the decisions of a method written in any language on the flights of "
                                   "'fuelhm-bench export' (use the same scenario options). The file has one row per "
                                   "flight: split (test or calibration), unit_id, flight_index, score, alarm and "
                                   "optionally guilt_<mode>; see docs/scoring.md, 'External methods'.")
    p.add_argument("decisions", help="decisions file (.parquet, .csv or .csv.gz)")
    add_scenario_options(p)
    p.add_argument("--exported", default=None, metavar="DIR",
                   help="the folder 'fuelhm-bench export' wrote: refuse to score unless the flights scored are "
                        "the ones exported there (its export.json: scenario, fidelity, seed, scale, minutes, tables)")
    p.add_argument("--out", default=None, help="also write the KPI tables into this directory")
    p.add_argument("--force", action="store_true", help="overwrite existing table files")
    p.set_defaults(func=run)


#: Tables written with --out besides the scorecard's (:data:`~fuelhm_bench.scoring.SCORECARD_TABLES`).
OUT_TABLES = ("headline_intervals",)


def run(args: argparse.Namespace) -> int:
    import contextlib

    from fuelhm_bench.cli._common import atomic_directory
    from fuelhm_bench.scoring import SCORECARD_TABLES
    from fuelhm_bench.scoring.export import table_files

    publish = contextlib.nullcontext(None)
    if args.out:  # checked before scoring; published (atomically) only when every table is written
        publish = atomic_directory(args.out, force=args.force, names=table_files((*SCORECARD_TABLES, *OUT_TABLES)),
                                   inputs={"DECISIONS": args.decisions})
    with publish as out_dir:
        return _run(args, out_dir)


def _run(args: argparse.Namespace, out_dir) -> int:
    from fuelhm_bench.benchmark.exchange import score_decisions
    from fuelhm_bench.scoring import headline_kpis, undefined_kpis
    from fuelhm_bench.scoring.bootstrap import scorecard_intervals

    def identify(tables) -> None:  # to compare with the export's export.json (or pass --exported)
        f = tables.fingerprint()
        print(f"flights scored: {f['scenario']}, {f['fidelity']}, seed {f['seed']}, {f['scored_units']} units, "
              f"{f['flight_minutes']:g} min; tables {f['tables_digest']}")

    card = score_decisions(args.decisions, args.scenario, exported=args.exported, on_tables=identify,
                           **scenario_kwargs(args))
    ci = scorecard_intervals(card).set_index("kpi")
    undefined = undefined_kpis(card)
    for kpi, value in headline_kpis(card).items():
        extra = (f"  [{ci.loc[kpi, 'ci_low']:.4g}, {ci.loc[kpi, 'ci_high']:.4g}]"
                 if kpi in ci.index and ci.loc[kpi, "ci_low"] == ci.loc[kpi, "ci_low"] else "")
        if kpi in undefined:
            extra = f"  (undefined: {undefined[kpi]})"
        print(f"{kpi:28s} {value:.4g}{extra}")
    if out_dir is not None:
        from fuelhm_bench.scoring import write_tables

        write_tables({**card.tables(), "headline_intervals": ci.reset_index()}, out_dir)
        print(f"tables: {args.out}")
    return 0
