"""``fuelhm-bench calibrate``: recalibrate the model on measured healthy flights (paper Fig. 7)."""

from __future__ import annotations

import argparse
import sys


def register(sub) -> None:
    from fuelhm_bench.cli._common import non_negative_int

    p = sub.add_parser(
        "calibrate", help="recalibrate the model's identifiable parameters on measured healthy flights",
        description="Fit the recalibration subset (null bias, slot widths, width transition, rated current, "
                    "cooling diaphragm, aerodynamic load) to measured healthy flights by least squares on the "
                    "velocity-gain curve: every flight is replayed through the model (measured current imposed, "
                    "rod position forced to the measured one each frame) and the model's velocity, differentiated "
                    "like the LVDT position, is compared with the measured one. Units are fitted separately; the "
                    "written model holds the fleet mean (YAML, loadable by 'simulate --model'). Prints the gap "
                    "(RMS residual over the velocity-gain curve) before and after, the fitted values and their "
                    "identifiability.")
    p.add_argument("flights", help="measured healthy flights (.parquet, .csv, .csv.gz; format: docs/data-format.md)")
    p.add_argument("--out", required=True, help="output model file (.yaml or .yml)")
    p.add_argument("--model", metavar="YAML", help="start model (default: nominal)")
    p.add_argument("--plot", metavar="FILE", help="write the curves before/after over the data (.png, .pdf or .svg, like Fig. 7)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the sample selection (default 0)")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.calibration.recalibrate import RECALIBRATION_PARAMETERS, CalibrationConfig, recalibrate
    from fuelhm_bench.calibration.report import calibration_summary, plot_curves
    from fuelhm_bench.cli._common import check_output, naming_file, progress_bar, usable_flights
    from fuelhm_bench.io.outputs import atomic_output
    from fuelhm_bench.physics.model import load_model, save_model

    inputs = {"FLIGHTS": args.flights, "--model": args.model}
    out = check_output(args.out, force=args.force, kind="yaml", what="model file", inputs=inputs)
    plot = check_output(args.plot, force=args.force, option="--plot", kind="image", what="figure",
                        inputs=inputs) if args.plot else None
    start = load_model(args.model) if args.model else None
    flights = usable_flights(args.flights)
    config = CalibrationConfig(seed=args.seed)
    n_par = len(RECALIBRATION_PARAMETERS)
    # Upper bound of the replays: one per iteration plus one Jacobian (n_par replays) per iteration.
    with progress_bar(config.max_iterations * (1 + n_par) + 1, "recalibrating", unit="replay") as bar, \
            naming_file(args.flights):
        result = recalibrate(flights, start, config=config, progress=bar.update)
    header = (f"fuelhm-bench calibrate {args.flights}: {len(flights)} flight(s), {len(result.unit_models)} unit(s)\n"
              f"gap (RMS velocity residual over the curve) {result.gap_before:.3f} -> {result.gap_fleet:.3f} mm/s "
              f"(fleet model), {result.gap_after:.3f} mm/s per unit")
    with atomic_output(out, force=args.force, option="--out") as tmp:
        save_model(result.model, tmp, header=header)
    if plot is not None:
        curves = {"before (start model)": result.v_before, "after (recalibrated per unit)": result.v_after}
        if len(result.unit_models) > 1:
            curves["after (fleet model written)"] = result.v_fleet
        with atomic_output(plot, force=args.force, option="--plot") as tmp:
            plot_curves(result.evaluation, curves, tmp, curve=result.curve,
                        title=f"velocity gain: gap {result.gap_before:.3f} -> {result.gap_after:.3f} mm/s per "
                              f"unit, {result.gap_fleet:.3f} mm/s fleet model")
    print(calibration_summary(result))
    print(f"wrote {out}" + (f" and {plot}" if plot is not None else ""))
    return 0
