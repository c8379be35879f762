"""``fuelhm-bench discrepancy``: which physical effect is the model missing?"""

from __future__ import annotations

import argparse
import sys


def register(sub) -> None:
    from fuelhm_bench.cli._common import non_negative_int, positive_int
    from fuelhm_bench.taxonomy import EFFECT_IDS

    p = sub.add_parser(
        "discrepancy", help="find the effect a model misses on measured healthy flights (model-discrepancy workflow)",
        description="Split the flights into fit and held-out flights, recalibrate the model per unit on the fit "
                    "flights, replay every flight through it to map where model and measurement disagree, fit "
                    "each candidate effect of the library jointly with the recalibration, rank the candidates by "
                    "BIC and accept the best only if it also shrinks the gap on the held-out flights, then look for "
                    "a second effect (forward selection). The verdict is 'effect' (a set of effects with their "
                    "parameters and shares of the gap; look-alikes named as equivalents with the test that "
                    "separates them), 'none' (what remains is at the level of healthy data from a plausible model) "
                    "or 'unexplained' (a significant gap no candidate explains: where it is, and the terms a "
                    "sparse regression of the residuals finds); recalibrated parameters beyond the manufacturing "
                    "dispersion are flagged, and caveats name what in the data weakens the verdict (flights "
                    "under 5 min, fewer than 3 held-out flights, one unit). --out DIR writes a Markdown report with figures and the augmented "
                    "model (YAML, loadable by 'simulate --model'); --json prints one JSON object on stdout.")
    p.add_argument("flights", help="measured healthy flights (.parquet, .csv, .csv.gz; format: docs/data-format.md)")
    p.add_argument("--model", metavar="YAML", help="model to examine (default: nominal)")
    p.add_argument("--out", metavar="DIR", help="write report.md, figures, result.json and augmented_model.yaml here")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout (logs on stderr)")
    p.add_argument("--seed", type=non_negative_int, default=0,
                   help="seed of the fit/held-out split and sample draws (default 0)")
    p.add_argument("--holdout", type=float, default=0.3, metavar="FRACTION",
                   help="share of the flights held out (default 0.3)")
    p.add_argument("--candidates", default=",".join(EFFECT_IDS), metavar="IDS",
                   help="comma-separated candidate effects (default: all)")
    p.add_argument("--jobs", type=positive_int, default=2, help="worker processes for the candidate fits (default 2)")
    p.add_argument("--force", action="store_true", help="overwrite existing files in --out")
    p.set_defaults(func=run)


OUTPUT_FILES = ("report.md", "augmented_model.yaml", "result.json", "curves.png", "residual_map.png", "regions.png")


def run(args: argparse.Namespace) -> int:
    import contextlib

    from fuelhm_bench.calibration.discrepancy import DiscrepancyConfig
    from fuelhm_bench.cli._common import atomic_directory
    from fuelhm_bench.errors import UnknownNameError, did_you_mean
    from fuelhm_bench.taxonomy import EFFECT_IDS

    candidates = tuple(c.strip() for c in args.candidates.split(",") if c.strip())
    for c in candidates:
        if c not in EFFECT_IDS:
            raise UnknownNameError(f"--candidates: unknown effect '{c}'. Allowed: {', '.join(EFFECT_IDS)}."
                                   f"{did_you_mean(c, EFFECT_IDS)}")
    if not candidates:
        raise UnknownNameError(f"--candidates must name at least one effect of {', '.join(EFFECT_IDS)}. Got "
                               f"'{args.candidates}' instead.")
    config = DiscrepancyConfig(holdout_fraction=args.holdout, candidates=candidates, n_jobs=args.jobs,
                               seed=args.seed)
    publish = contextlib.nullcontext(None)
    if args.out:  # checked now; published (atomically) only when every file is written
        publish = atomic_directory(args.out, force=args.force, names=OUTPUT_FILES,
                                   inputs={"FLIGHTS": args.flights, "--model": args.model})
    with publish as out_dir:
        return _run(args, config, out_dir)


def _run(args: argparse.Namespace, config, out_dir) -> int:
    from pathlib import Path

    from fuelhm_bench.calibration.discrepancy import find_discrepancy
    from fuelhm_bench.calibration.report import json_text, write_discrepancy_report
    from fuelhm_bench.cli._common import naming_file, progress_bar, usable_flights
    from fuelhm_bench.physics.model import load_model, save_model

    model = load_model(args.model) if args.model else None
    flights = usable_flights(args.flights)

    def log(msg: str) -> None:
        print(msg, file=sys.stderr)

    with progress_bar(1 + len(config.candidates), "fitting", unit="fit") as bar, naming_file(args.flights):
        result = find_discrepancy(flights, model, config=config, progress=bar.update, log=log)
    payload = result.as_json()
    if out_dir is not None:
        model_path = Path(args.out) / "augmented_model.yaml"  # where it is published (written in out_dir first)
        save_model(result.model, Path(out_dir) / model_path.name, overwrite=True,
                   header=f"fuelhm-bench discrepancy {args.flights}: effect {result.effect}; held-out gap "
                          f"{result.gap_before:.3f} -> {result.gap_after:.3f} mm/s")
        report = Path(args.out) / write_discrepancy_report(result, out_dir, model_file=str(model_path),
                                                           data_name=str(args.flights)).name
        payload["model_file"] = str(model_path)
        payload["report"] = str(report)
        log(f"wrote {report} and {model_path}")
    if args.json:
        print(json_text(payload))
    else:
        print(f"verdict: {result.verdict}" + (f" -- {result.unexplained}" if result.unexplained else ""))
        print(f"effect: {result.effect}")
        for k, v in result.parameters.items():
            print(f"  {k} = {v:.5g}")
        for m in result.effect_set[1:]:
            print(f"  + {m.effect}: " + ", ".join(f"{k} = {v:.5g}" for k, v in m.parameters.items()))
        for e in result.equivalents:
            print(f"equivalent: {e.alternative} (test: {e.test})")
        for f in result.flags:
            print(f"flag: unit {f.unit} {f.path} = {f.value:.5g} ({f.z:+.1f} sigma): likely absorbing a missing effect")
        for c in result.caveats:
            print(f"caveat ({c.code}): {c.message}")
        if result.probe is not None:
            print("probe: " + ", ".join(f"{t} ({c:+.3g})" for t, c in zip(result.probe.terms, result.probe.coefficients))
                  + f"; closes {100 * result.probe.gap_closed:.0f} % of the held-out gap")
        print(f"region: {result.region}")
        print(f"held-out gap: {result.gap_before:.3f} (input) -> {result.gap_recalibrated:.3f} (recalibrated) -> "
              f"{result.gap_after:.3f} mm/s ({100 * result.gap_reduction:.0f} % smaller)")
        print("ranking (BIC, dBIC vs none, held-out gap):")
        for c in result.ranking:
            print(f"  {c.label:18s} {c.bic:12.1f} {c.delta_bic:10.1f} {c.gap_after:8.3f}"
                  f"{'  eligible' if c.eligible else ''}")
    return 0
